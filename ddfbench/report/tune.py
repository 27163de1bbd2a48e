"""`python -m ddfbench.report.tune RESULTS/tune --out reports/tune`: the tuning studies (`+experiment=tune`).

Writes into --out, from the records alone:
  trials.md, trials.csv  every trial per model in the order run: the values drawn, the objective
                         (chamfer L2 x10^3 of the final reconstruction; empty: the penalty), steps, fit s;
                         a tune record with no drawn values is the preset itself at the same budget
                         (`kind` preset: `+experiment=tune model=<m> hydra.mode=RUN`)
  best.md                per model: trials, fit seconds per trial, the best trial's objective and values
                         beside the preset's own and the preset's objective (equal budgets: a study whose
                         trial count or fit seconds differ from the others' is named there)
  space.md               each model's search space as conf/model/<model>.yaml declares it
  tune.png               objective per trial and the best so far, one line per model
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any

import pandas as pd

from ddfbench.core import plugins
from ddfbench.evaluate.metric_registry import objective_value
from ddfbench.fit.tune import search_space
from ddfbench.run.runs import code_commits, find_records

OBJECTIVE = "chamfer_l2"  # conf/experiment/tune.yaml `objective`
SCALE = 1e3  # printed as x10^3, as in every report table


def trials(records: list[dict[str, Any]]) -> pd.DataFrame:
    """One row per run: model, kind (trial | preset), trial (0-based by start time; preset: NaN), each drawn
    value, objective, steps, fit_s, max_seconds."""
    rows = []
    for rec in sorted(records, key=lambda r: (str(r.get("model")), str(r.get("started")))):
        model = str(rec.get("model"))
        space = search_space(model)
        drawn = dict(o.split("=", 1) for o in rec.get("overrides") or [] if o.split("=", 1)[0] in space)
        fit = rec.get("fit") or {}
        rows.append({"model": model, "kind": "trial" if drawn else "preset", **drawn,
                     "objective": objective_value(rec, OBJECTIVE) * SCALE, "status": rec.get("status"), "steps": fit.get("steps"),
                     "fit_s": (rec.get("cost") or {}).get("fit_s"),
                     "max_seconds": ((rec.get("config") or {}).get("train") or {}).get("max_seconds")})
    df = pd.DataFrame(rows)
    if not df.empty:
        is_trial = df["kind"] == "trial"
        df.insert(2, "trial", df[is_trial].groupby("model").cumcount().astype("Int64"))
    return df


def _preset_value(model: str, path: str) -> Any:
    node: Any = plugins.model_defaults(model)
    for key in path.split(".")[1:]:
        node = node.get(key) if isinstance(node, dict) else None
    return node


def provenance(records: list[dict[str, Any]], records_dir: str) -> str:
    """One line: how many records, from where, which code commits, threads and CPU they ran with."""
    env = [r.get("env") or {} for r in records]
    commits = [sha[:7] for sha in code_commits(records)]
    threads = sorted({str(e.get("threads")) for e in env})
    cpus = sorted({str(e.get("cpu")) for e in env})
    return (f"{len(records)} records from `{records_dir}` (code {', '.join(commits)}; threads {', '.join(threads)}; "
            f"cpu {', '.join(cpus)}).")


def best(df: pd.DataFrame, header: str = "") -> list[str]:
    """Markdown lines: per model the best trial, its values beside the preset's, and the budget check."""
    lines = ["# Best trial per model", "", *([header, ""] if header else [])]
    studies = df[df["kind"] == "trial"]
    budgets = {m: (len(g), tuple(sorted(set(df.loc[df["model"] == m, "max_seconds"])))) for m, g in studies.groupby("model")}
    if len(set(budgets.values())) > 1:
        lines += ["**Unequal budgets**: " + "; ".join(f"{m}: {n} trials at {s} s" for m, (n, s) in budgets.items()), ""]
    else:
        n, secs = next(iter(budgets.values()))
        lines += [f"Every model: {n} trials, {', '.join(str(s) for s in secs)} s of fit each (wall clock).", ""]
    for model, group in studies.groupby("model"):
        top = group.loc[group["objective"].idxmin()]
        preset = df[(df["model"] == model) & (df["kind"] == "preset")]
        lines += [f"## {model}: trial {int(top['trial'])}, CD-L2 x10^3 {top['objective']:.4g} "
                  f"({int(top['steps'])} steps, {top['fit_s']:.1f} s)", ""]
        if len(preset):
            lines += [f"The preset's own values at the same budget: CD-L2 x10^3 {preset['objective'].iloc[0]:.4g} "
                      f"({int(preset['steps'].iloc[0])} steps).", ""]
        lines += ["| key | best | preset |", "|---|---|---|"]
        lines += [f"| {path} | {top[path]} | {_preset_value(model, path)} |" for path in search_space(model)]
        lines.append("")
    return lines


def space_lines(models: list[str]) -> list[str]:
    lines = ["# Search spaces (conf/model/<model>.yaml, experiments.tune)", ""]
    for model in models:
        lines += [f"## {model}", "", "| key | distribution | values |", "|---|---|---|"]
        lines += [f"| {p} | {k} | {v} |" for p, (k, v) in search_space(model).items()]
        lines.append("")
    return lines


def plot(df: pd.DataFrame, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4))
    for model, group in df[df["kind"] == "trial"].groupby("model"):
        line, = ax.plot(group["trial"], group["objective"], "o", alpha=0.5, label=f"{model} trials")
        ax.plot(group["trial"], group["objective"].cummin(), "-", color=line.get_color(), label=f"{model} best so far")
        for value in df.loc[(df["model"] == model) & (df["kind"] == "preset"), "objective"]:
            ax.axhline(value, color=line.get_color(), ls=":", lw=1, label=f"{model} preset")
    ax.set_yscale("log")
    ax.set_xlabel("trial")
    ax.set_ylabel("CD-L2 x10^3 (final reconstruction)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write(records_dir: str, out: str) -> pd.DataFrame:
    """Write the four files for the records below records_dir; return the trials table."""
    records = [r for r in find_records(records_dir) if r.get("experiment") == "tune"]
    if not records:
        raise FileNotFoundError(f"{records_dir}: no records of experiment tune")
    df = trials(records)
    os.makedirs(out, exist_ok=True)
    df.to_csv(os.path.join(out, "trials.csv"), index=False)
    with open(os.path.join(out, "trials.md"), "w") as fh:
        for model, group in df.groupby("model"):
            cols = ["kind", "trial", *search_space(str(model)), "objective", "status", "steps", "fit_s"]
            fh.write(f"## {model}\n\n{group[cols].to_markdown(index=False, floatfmt='.4g')}\n\n")
    with open(os.path.join(out, "best.md"), "w") as fh:
        fh.write("\n".join(best(df, provenance(records, records_dir))) + "\n")
    with open(os.path.join(out, "space.md"), "w") as fh:
        fh.write("\n".join(space_lines(sorted(df["model"].unique()))) + "\n")
    plot(df, os.path.join(out, "tune.png"))
    return df


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.tune", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("records", help="the tune records, e.g. results/tune")
    parser.add_argument("--out", default="reports/tune")
    args = parser.parse_args(argv)
    try:
        df = write(args.records, args.out)
    except FileNotFoundError as err:
        print(f"ddfbench.report.tune: {err}", file=sys.stderr)
        return 2
    for model, group in df[df["kind"] == "trial"].groupby("model"):
        b = group["objective"].min()
        print(f"{model}: {len(group)} trials, best CD-L2 x10^3 {b:.4g}" if math.isfinite(b) else f"{model}: no trial")
    return 0


if __name__ == "__main__":
    sys.exit(main())
