"""`python -m ddfbench.report.tune RESULTS/tune --out reports/tune`: the tuning studies (`+experiment=tune`).

Writes into --out (default: RESULTS/tune/report, beside the records), from the records alone:
  trials.csv, trials.md  every trial per model in the order run: the values drawn, the objective
                         (chamfer L2 x10^3 of the final reconstruction; empty: the penalty), steps, fit s;
                         a tune record with no drawn values is the preset itself at the same budget
                         (`kind` preset: `+experiment=tune model=<m> hydra.mode=RUN`)
  study.json             what the tables read besides the trials: the provenance line, each model's search space
                         as conf/model/<model>.yaml declared it and the preset's values (its preset run's config;
                         without one, the YAML's)
  best.md                per model: trials, fit seconds per trial, the best trial's objective and values
                         beside the preset's own and the preset's objective (equal budgets: a study whose
                         trial count or fit seconds differ from the others' is named there)
  space.md               each model's search space, from study.json
  tune.png               objective per trial and the best so far, one line per model

trials.csv and study.json are the study's compact record: `rebuild` (`regenerate --from-records`) writes the other
files from them alone, so a study regenerates on a fresh clone although a later commit changes a preset or a space
(a wall-clock study cannot be run again to the same trials). Writing them reads the search spaces from conf/, so a
study is written at the code commit it ran at, as every report is.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from typing import Any

import pandas as pd

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.evaluate.metric_registry import objective_value
from ddfbench.fit.tune import search_space
from ddfbench.report.checked_json import checked_json_object
from ddfbench.report.compact import folders_holding
from ddfbench.report.tables import pipe_lines
from ddfbench.run.checks import writable_folder
from ddfbench.run.runs import code_commits, find_records

OBJECTIVE = "chamfer_l2"  # conf/experiment/tune.yaml `objective`
SCALE = 1e3  # printed as x10^3, as in every report table
TRIALS_FILE = "trials.csv"
STUDY_FILE = "study.json"
COLUMNS = ("model", "kind", "trial", "objective", "status", "steps", "fit_s", "max_seconds")  # besides the drawn values


def _drawn(record: dict[str, Any], space: dict[str, Any]) -> dict[str, str]:
    """{config path: value as overridden} of the record's overrides that its model's search space draws."""
    return dict(o.split("=", 1) for o in record.get("overrides") or [] if o.split("=", 1)[0] in space)


def trials(records: list[dict[str, Any]]) -> pd.DataFrame:
    """One row per run: model, kind (trial | preset), trial (0-based by start time; preset: <NA>), each drawn
    value (as overridden, a string), objective, steps, fit_s, max_seconds."""
    rows = []
    for rec in sorted(records, key=lambda r: (str(r.get("model")), str(r.get("started")))):
        model = str(rec.get("model"))
        drawn = _drawn(rec, search_space(model))
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


def _value_at(config: Any, path: str) -> Any:
    """The value at a search-space path (`model.<key>[.<key>]`) of a model config; None where it has none."""
    for key in path.split(".")[1:]:
        config = config.get(key) if isinstance(config, dict) else None
    return config


def provenance(records: list[dict[str, Any]], records_dir: str) -> str:
    """One line: how many records, from where (`<out_dir>/<folder name>`: a machine's folder means nothing on a
    clone), which code commits, threads and CPU they ran with."""
    env = [r.get("env") or {} for r in records]
    commits = [sha[:7] for sha in code_commits(records)]
    threads = sorted({str(e.get("threads")) for e in env})
    cpus = sorted({str(e.get("cpu")) for e in env})
    where = f"<out_dir>/{os.path.basename(os.path.normpath(records_dir))}"
    return (f"{len(records)} records from `{where}` (code {', '.join(commits)}; threads {', '.join(threads)}; "
            f"cpu {', '.join(cpus)}).")


def study(records: list[dict[str, Any]], records_dir: str, models: list[str]) -> dict[str, Any]:
    """study.json: {"provenance": line, "spaces": {model: {path: [kind, values]}}, "presets": {model: {path:
    value}}}, the presets' values from each model's preset run (its record's config), else from its YAML."""
    spaces = {model: search_space(model) for model in models}
    presets, by_start = {}, sorted(records, key=lambda r: str(r.get("started")))  # the first preset run, as in best.md
    for model, space in spaces.items():
        run = next((r for r in by_start if str(r.get("model")) == model and not _drawn(r, space)), None)
        config = ((run.get("config") or {}).get("model") if run else None) or plugins.model_defaults(model)
        presets[model] = {path: _value_at(config, path) for path in space}
    return {"provenance": provenance(records, records_dir),
            "spaces": {model: {path: [kind, values] for path, (kind, values) in space.items()}
                       for model, space in spaces.items()},
            "presets": presets}


def best(df: pd.DataFrame, head: dict[str, Any]) -> list[str]:
    """Markdown lines: per model the best trial, its values beside the preset's, and the budget check."""
    lines = ["# Best trial per model", "", head["provenance"], ""]
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
        lines += pipe_lines(["key", "best", "preset"],
                            [[f"{path}", f"{top[path]}", f"{value}"] for path, value in head["presets"][model].items()])
        lines.append("")
    return lines


def space_lines(spaces: dict[str, dict[str, list[Any]]]) -> list[str]:
    """Markdown lines: each model's search space, one row per drawn key."""
    lines = ["# Search spaces (conf/model/<model>.yaml, experiments.tune)", ""]
    for model, space in spaces.items():
        lines += [f"## {model}", ""]
        lines += pipe_lines(["key", "distribution", "values"],
                            [[f"{p}", f"{k}", f"{v}"] for p, (k, v) in space.items()])
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


def write_tables(out: str, df: pd.DataFrame, head: dict[str, Any], draw: bool = True) -> None:
    """Write trials.csv, trials.md, best.md, space.md (and with draw, tune.png) of a study into out."""
    os.makedirs(out, exist_ok=True)
    df.to_csv(os.path.join(out, TRIALS_FILE), index=False)
    with open(os.path.join(out, "trials.md"), "w") as fh:
        for model, group in df.groupby("model"):
            cols = ["kind", "trial", *head["spaces"][str(model)], "objective", "status", "steps", "fit_s"]
            fh.write(f"## {model}\n\n{group[cols].to_markdown(index=False, floatfmt='.4g')}\n\n")
    with open(os.path.join(out, "best.md"), "w") as fh:
        fh.write("\n".join(best(df, head)) + "\n")
    with open(os.path.join(out, "space.md"), "w") as fh:
        fh.write("\n".join(space_lines(head["spaces"])) + "\n")
    if draw:
        plot(df, os.path.join(out, "tune.png"))


def _head_problem(head: dict[str, Any]) -> str | None:
    """What makes study.json's spaces and presets unusable, else None."""
    for model, space in head["spaces"].items():
        if not isinstance(space, dict) or any(not (isinstance(d, list) and len(d) == 2 and isinstance(d[0], str)
                                                   and isinstance(d[1], list)) for d in space.values()):
            return f"spaces.{model} must map each key to [distribution, [values]]"
        if not isinstance(head["presets"].get(model), dict) or list(head["presets"][model]) != list(space):
            return f"presets.{model} must give a value for each key of spaces.{model}, in its order"
    extra = sorted(set(head["presets"]) - set(head["spaces"]))
    return f"presets.{extra[0]} has no search space" if extra else None


def _trials_problem(df: pd.DataFrame, spaces: dict[str, Any]) -> str | None:
    """What makes a trials table unusable with these spaces, else None."""
    missing = [c for c in COLUMNS if c not in df.columns]
    if missing:
        return f"no column {', '.join(missing)}"
    bad_kind = sorted(set(map(str, df["kind"])) - {"trial", "preset"})
    if bad_kind:
        return f"kind {bad_kind[0]!r} is not trial or preset"
    for model in sorted(set(map(str, df["model"])) | set(spaces)):
        rows = df[df["model"].astype(str) == model]
        trial_rows = rows[rows["kind"] == "trial"]
        if model not in spaces:
            return f"model {model} has no search space in {STUDY_FILE}"
        absent = [c for c in spaces[model] if c not in df.columns]
        if absent:
            return f"no column {', '.join(absent)} of {model}'s space"
        if trial_rows.empty:
            return f"model {model} has no trial row"
        numbers = pd.to_numeric(trial_rows["trial"], errors="coerce")
        if numbers.isna().any() or (numbers % 1 != 0).any() or numbers.duplicated().any():
            return f"{model}'s trial numbers must be whole, given and distinct"
        if rows.loc[rows["kind"] != "trial", "trial"].notna().any():
            return f"{model}'s preset rows must leave trial empty"
    not_numbers = [c for c in ("objective", "steps", "fit_s", "max_seconds") if not pd.api.types.is_numeric_dtype(df[c])]
    return f"column {', '.join(not_numbers)} must hold numbers" if not_numbers else None


def read(folder: str) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The trials table and study.json of a study folder, as write_tables takes them (drawn values as the strings
    overridden; only an empty cell is missing); InputError naming the file that is not one."""
    path = os.path.join(folder, STUDY_FILE)
    head = checked_json_object(path, {"provenance": str, "spaces": dict, "presets": dict})
    problem = _head_problem(head)
    if problem:
        raise InputError(f"{path}: {problem}")
    path = os.path.join(folder, TRIALS_FILE)
    try:
        drawn = [c for c in pd.read_csv(path, nrows=0).columns if c not in COLUMNS]
        df = pd.read_csv(path, dtype=dict.fromkeys(drawn, str), keep_default_na=False, na_values=[""])
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: not a trials table ({exc})") from exc
    problem = _trials_problem(df, head["spaces"])
    if problem:
        raise InputError(f"{path}: {problem}")
    df["trial"] = df["trial"].astype("Int64")
    return df, head


def rebuild(folder: str, into: str, draw: bool = True) -> None:
    """Write the tables of a study folder's trials.csv and study.json into `into`, running nothing."""
    write_tables(into, *read(folder), draw=draw)


def holds_study(folder: str) -> bool:
    """Whether folder holds a study's compact record (trials.csv and study.json)."""
    return all(os.path.isfile(os.path.join(folder, name)) for name in (TRIALS_FILE, STUDY_FILE))


def folders(reports: str) -> list[str]:
    """Every folder below reports (any depth) that holds a study's compact record, sorted."""
    return folders_holding(reports, TRIALS_FILE, STUDY_FILE)


def write(records_dir: str, out: str) -> pd.DataFrame:
    """Write the study of the records below records_dir into out: its compact record (trials.csv, study.json), then
    the tables from those as read back, so a rebuild writes the same bytes; return the trials table."""
    records = [r for r in find_records(records_dir) if r.get("experiment") == "tune"]
    if not records:
        raise FileNotFoundError(f"{records_dir}: no records of experiment tune")
    df = trials(records)
    os.makedirs(out, exist_ok=True)
    df.to_csv(os.path.join(out, TRIALS_FILE), index=False)
    with open(os.path.join(out, STUDY_FILE), "w", encoding="utf-8") as fh:
        json.dump(study(records, records_dir, sorted(df["model"].unique())), fh, indent=1)
        fh.write("\n")
    df, head = read(out)
    write_tables(out, df, head)  # trials.csv again, from the table as read back: what a rebuild writes
    return df


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.tune", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("records", help="the tune records, e.g. results/tune")
    parser.add_argument("--out", help="folder for the tables (default: beside the records, RECORDS/report; "
                        "--out reports/tune to publish)")
    args = parser.parse_args(argv)
    out = args.out or os.path.join(args.records, "report")
    try:
        writable_folder(out, "--out ")
        df = write(args.records, out)
    except (FileNotFoundError, InputError) as err:
        print(f"ddfbench.report.tune: {err}", file=sys.stderr)
        return 2
    for model, group in df[df["kind"] == "trial"].groupby("model"):
        b = group["objective"].min()
        print(f"{model}: {len(group)} trials, best CD-L2 x10^3 {b:.4g}" if math.isfinite(b) else f"{model}: no trial")
    return 0


if __name__ == "__main__":
    sys.exit(main())
