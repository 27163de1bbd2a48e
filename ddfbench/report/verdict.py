"""`python -m ddfbench.report.verdict [--reports reports] [--readme README.md] [--check]`: the verdict table, generated
from committed records only, into reports/verdict.md and between the README's verdict markers.

One row per preset and budget: the short budget is `reports/default` (each family's `first_look` level, about a
minute on 2 cores, with renders), the preset's own budget is `reports/shape_suite` (its fit_steps) on the bunny,
beside its geometric mean over the suite's evaluation shapes, with the frame columns from `reports/render_time` (the
same preset at the same fit_steps, its largest images; `reports/render_shapes` for a preset render_time lacks). The
presets the shape suite lacks get a row from `reports/grid_encodings` (the feature-grid DDF and SDF; equal steps
for every family), beside its geometric mean over that report's shapes, and their own-budget row from
`reports/gan_epochs` (the thesis GAN at its 40 epochs, the bunny only). Per row: CD-L2 as a multiple
of the noise floor (the mesh against a resample of itself at the same point count) with the 95 % t interval over
seeds, the point-to-surface chamfer, F@0.005, depth MAE and mask IoU where the run rendered, fit or build seconds,
warm frame seconds, bytes. A preset with a run on the bunny that gave no mesh or one off the shape is not ranked: its
row says "not converged" when every run gave none, else in how many runs; the shapes left out of the last column for
such a run are counted. The footnote names the device, threads, point counts and code commits of the records, and
the seconds one fixed build (the grid SDF's on the bunny) took in each set, since seconds differ by machine and load.
--check exits 1 when reports/verdict.md or the README block differs from what the records give.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any, Callable

from ddfbench.core.errors import InputError
from ddfbench.evaluate.metric_registry import by_name
from ddfbench.report import compact
from ddfbench.report.across_shapes import fmt, geometric
from ddfbench.report.records import (
    NOT_CONVERGED,
    Record,
    as_float,
    at_largest_image,
    no_result,
    ok_records,
    shape_name,
)
from ddfbench.report.shape_suite import cells, cells_without_result
from ddfbench.report.stats import summarize_values
from ddfbench.report.tables import budget_label, pipe_table

START, END = "<!-- verdict:start (python -m ddfbench.report.verdict) -->", "<!-- verdict:end -->"
SHORT, FULL, FRAMES, OTHER_FRAMES, GRID = "default", "shape_suite", "render_time", "render_shapes", "grid_encodings"
EPOCHS = "gan_epochs"
SAME_WORK = "grid_sdf"  # a build with no training: the same work wherever its bytes are the same
SHAPE = "bunny"
FAMILY_ORDER = ["mesh", "grid_sdf", "neural_sdf", "ddf", "gan_sdf"]  # the reference first, then the fields
HEADER = ["preset", "budget", "CD-L2 / floor, geometric mean [95 %]", "p2s CD-L2 ×10³", "F@0.005",
          "depth MAE ×10³ / mask IoU", "fit or build s", "warm frame s", "bytes",
          "over the suite's shapes: CD-L2 ×10³ [95 %]"]


def _floor(rec: Record) -> float:
    return float(((rec.get("metrics") or {}).get("noise_floor") or {}).get("chamfer_l2") or math.nan)


def _mean(recs: list[Record], metric: str, scale: float = 1.0, spec: str = ".3g") -> str:
    """The metric's mean over the records, times scale, formatted by spec ('–' where none is finite)."""
    s = summarize_values(by_name()[metric].read(r) for r in recs)
    return "–" if not math.isfinite(s.mean) else format(s.mean * scale, spec)


def _ratio_to_floor(recs: list[Record]) -> str:
    """Geometric mean over seeds of CD-L2 / its noise floor, with the exponentiated t interval of the mean log
    (never below 0)."""
    ratios = {str(i): by_name()["chamfer_l2"].read(r) / _floor(r) for i, r in enumerate(recs)}
    return fmt(geometric({k: v for k, v in ratios.items() if math.isfinite(v)}))


def _steps(recs: list[Record]) -> str:
    """The records' fixed work: 'built', their epochs where every fit was budgeted in epochs, else their steps."""
    epochs = {as_float((r.get("fit") or {}).get("epochs")) for r in recs}
    if recs and all(budget_label(r) == "epochs" for r in recs) and all(map(math.isfinite, epochs)):
        return " / ".join(f"{n:,}" for n in sorted({round(e) for e in epochs})) + " epochs"
    steps = sorted({int((r.get("fit") or {}).get("steps") or 0) for r in recs})
    if steps == [0] or steps == [1]:
        return "built"
    return " / ".join(f"{n:,}" for n in steps) + " steps"


def same_preset(a: Record, b: Record) -> bool:
    """Whether two records ran the same model config: equal on every key both have (a key one of them lacks was added
    to the family since, at its default)."""
    ma, mb = (a.get("config") or {}).get("model") or {}, (b.get("config") or {}).get("model") or {}
    return all(ma[k] == mb[k] for k in ma.keys() & mb.keys())


def largest_frames(frames: list[Record], like: list[Record]) -> list[Record]:
    """render_time's records of the same preset as `like` (same model name and config, same steps) on the bunny, at
    the largest image size: the own-budget row's frames."""
    if not like:
        return []
    steps = {(r.get("fit") or {}).get("steps") for r in like}
    return at_largest_image(r for r in frames if r.get("model") == like[0].get("model") and shape_name(r) == SHAPE
                            and same_preset(r, like[0]) and (r.get("fit") or {}).get("steps") in steps)[1]


def rows(short: list[Record], full: list[Record], frames: list[Record] = (),
         grid: list[Record] = (), epochs: list[Record] = ()) -> list[list[str]]:
    """The table's rows: per model of the record sets, its short-budget row and its own-budget row (whose frame
    columns come from the largest images of the same preset at the same fit_steps in `frames`); for a model the shape
    suite lacks, its own-budget row from `epochs` (gan_epochs: its fit budgeted in epochs, no column over shapes)
    and its row from `grid` (grid_encodings: equal steps for every family)."""
    in_suite = {x.get("model") for x in full}
    grid, epochs = ([r for r in recs if r.get("model") not in in_suite] for recs in (grid, epochs))
    budgets = ((short, "short", False), (full, "own", True), (epochs, "own", False), (grid, "same grid", True))
    over_shapes = [cells(recs, "chamfer_l2") if across else {} for recs, _, across in budgets]
    # every model that ran, ok or not: a model whose every run failed still gets its rows
    family = {str(r.get("model")): str(r.get("family")) for r in [*short, *full, *epochs, *grid]}
    models = sorted(family, key=lambda m: (FAMILY_ORDER.index(family[m]) if family[m] in FAMILY_ORDER
                                           else len(FAMILY_ORDER), m))
    out = []
    for model in models:
        for (recs, label, _), over in zip(budgets, over_shapes):
            runs = [r for r in recs if r.get("model") == model and shape_name(r) == SHAPE]
            mine = ok_records(runs)
            if not runs:
                continue
            budget = f"{label}: {_steps(mine) if mine else 'no run finished'}"
            failed = len(runs) - len(mine) + sum(no_result(r) for r in mine)  # a run that failed gave no result either
            if failed:
                steps = sorted({(r.get("fit") or {}).get("steps") for r in mine})
                how = "failed" if not mine else NOT_CONVERGED if failed == len(runs) else "no result, not ranked"
                said = f"{how} ({failed} of {len(runs)} runs" + (f", steps {steps})" if steps else ")")
                out.append([model, budget, said] + ["–"] * (len(HEADER) - 3))
                continue
            suite = "–"
            if model in over:
                suite = fmt(geometric(over[model]), 1e3)
                missed = sum(1 for row in cells_without_result(recs) if row["model"] == model)
                left_out = f"; {missed} shape{'s' if missed > 1 else ''} left out (a run gave no result)"
                suite += left_out if missed else ""
            rendered = mine if label == "short" else largest_frames(list(frames), mine)
            image = (f"{_mean(rendered, 'depth_mae', 1e3)} / {_mean(rendered, 'mask_iou', 1.0, '.3f')}"
                     if _mean(rendered, "mask_iou") != "–" else "–")
            out.append([model, budget, _ratio_to_floor(mine), _mean(mine, "p2s_chamfer_l2", 1e3),
                        _mean(mine, "fscore@0.005", 1.0, ".3f"), image, _mean(mine, "fit_s"),
                        _mean(rendered, "render_warm_s"), _mean(mine, "storage_bytes", 1.0, ".3g"), suite])
    return out


def _values(recs: list[Record], field: Callable[[Record], Any]) -> str:
    """The distinct values of one field over the records, sorted and joined."""
    return ", ".join(sorted({str(field(r)) for r in recs}))


def footnote(sets: dict[str, list[Record]]) -> str:
    parts = []
    for name, recs in sets.items():
        if not recs:
            parts.append(f"`reports/{name}`: no records committed")
            continue
        parts.append(f"`reports/{name}` {len(recs)} records, {_values(recs, lambda r: r['env'].get('cpu'))}, "
                     f"threads {_values(recs, lambda r: r['env'].get('threads'))}, "
                     f"{_values(recs, lambda r: r['config']['eval'].get('n_points'))} points, "
                     f"code {_values(recs, lambda r: str(r['env'].get('code_sha'))[:7])}")
    return ("Generated by `python -m ddfbench.report.verdict` from committed records (the bunny, mean over seeds). "
            "floor: the metric's noise floor, GT against its own resample (1: as close as the points can tell). "
            "short: the default run (`first_look` levels, 64² frames); own: the shape suite's fit_steps, the last "
            "column the geometric mean over its shapes (per axis in `reports/shape_suite/report.md`), the frames "
            "`reports/render_time`'s largest (else `reports/render_shapes`'), same preset and steps; own in epochs: "
            "`reports/gan_epochs` (the thesis GAN, bunny only); same grid: `reports/grid_encodings` (every family at "
            "3,000 steps) for presets the suite lacks, the last column over its shapes. Records: "
            + "; ".join(parts) + "." + same_work_seconds(sets))


def same_work_seconds(sets: dict[str, list[Record]]) -> str:
    """A sentence giving the seconds one fixed work took in each record set that timed it: the grid SDF's build on
    the bunny (no training), in the sets whose runs built it at the first such set's bytes (so resolution) and
    threads, so that a reader sees how far the sets' machines and loads differ before comparing seconds across
    them; '' unless two or more sets timed that work."""
    timed = {}
    for name, recs in sets.items():
        mine = [r for r in ok_records(recs) if r.get("model") == SAME_WORK and shape_name(r) == SHAPE]
        if mine:
            timed[name] = mine
    works = {name: {(r["cost"].get("storage_bytes"), r["env"].get("threads")) for r in recs}
             for name, recs in timed.items()}
    same = [name for name in timed if len(works[name]) == 1 and works[name] == next(iter(works.values()))]
    if len(same) < 2:
        return ""
    took = ", ".join(f"{_mean(timed[name], 'fit_s')} s in `reports/{name}`" for name in same)
    return (" Seconds are each record set's own, on its machine under its load (a record names the CPU architecture, "
            f"not the model), so compare them within one set: the same build, the grid SDF's on the {SHAPE}, took "
            f"{took}.")


def frame_records(sets: dict[str, list[Record]]) -> list[Record]:
    """render_time's records, and render_shapes' of the models render_time has none of (one experiment a model)."""
    timed = {r.get("model") for r in ok_records(sets[FRAMES])}
    return sets[FRAMES] + [r for r in sets[OTHER_FRAMES] if r.get("model") not in timed]


def table(reports: str) -> str:
    sets = {name: compact.records_of(os.path.join(reports, name)) for name in (SHORT, FULL, FRAMES, OTHER_FRAMES, GRID,
                                                                                 EPOCHS)}
    return pipe_table(HEADER, rows(sets[SHORT], sets[FULL], frame_records(sets), sets[GRID], sets[EPOCHS])) + "\n" \
        + footnote(sets) + "\n"


def with_block(readme: str, block: str) -> str:
    """The README text with the block between the markers replaced; InputError when the markers are missing."""
    if START not in readme or END not in readme:
        raise InputError(f"the README has no verdict markers ({START} ... {END})")
    head, rest = readme.split(START, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{START}\n{block}{END}{tail}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.verdict", description=__doc__.split("\n")[0])
    parser.add_argument("--reports", default="reports")
    parser.add_argument("--readme", default="README.md")
    parser.add_argument("--check", action="store_true", help="exit 1 when a committed file differs from the records")
    args = parser.parse_args(argv)
    try:  # a damaged records file (read_compact names it): one line, nothing written
        block = table(args.reports)
    except InputError as exc:
        print(f"ddfbench.report.verdict: {exc}", file=sys.stderr)
        return 2
    verdict_path = os.path.join(args.reports, "verdict.md")
    text = "# Verdict\n\n" + block
    try:
        with open(args.readme) as fh:
            new_readme = with_block(fh.read(), block)
    except (OSError, InputError) as exc:
        print(f"ddfbench.report.verdict: {args.readme}: {getattr(exc, 'strerror', None) or exc}", file=sys.stderr)
        return 2
    if args.check:
        differ = [p for p, want in ((verdict_path, text), (args.readme, new_readme))
                  if not os.path.isfile(p) or open(p).read() != want]
        for path in differ:
            print(f"ddfbench.report.verdict: {path} differs from the table its records give", file=sys.stderr)
        return 1 if differ else 0
    with open(verdict_path, "w") as fh:
        fh.write(text)
    with open(args.readme, "w") as fh:
        fh.write(new_readme)
    print(f"wrote {verdict_path} and the verdict block of {args.readme}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
