"""python -m ddfbench.bench.compare --before A.json A2.json [...] --after B.json B2.json [...] [--out F.md]

Did a change move the benchmark? Bench JSON files of the code before and after (at least two runs of
each, interleaved on one idle host, same device, sizes and threads) are compared row by row. A row's
run-to-run noise is the range (max - min) of a quantity over the runs of one code, and the row is
"within noise" when the change of its mean is no larger than the larger of the two codes' ranges: the
code moved it no more than running the same code again did. (Overlapping ranges would be too strict a
test: two runs of each code, all four from one distribution, fail to overlap one time in three.)
Each row is judged on its same-process ratio and on its own figure: a ratio can move because its
reference did while the figure stayed.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from typing import Sequence

from ddfbench.bench.table import number
from ddfbench.core.errors import InputError

SAME = (("options", "device"), ("options", "sizes"), ("env", "threads"))  # what every compared run must share


def _mean(xs: Sequence[float]) -> float:
    return sum(xs) / len(xs)


def change(before: Sequence[float], after: Sequence[float]) -> float:
    """mean(after) / mean(before) - 1 (NaN when the mean before is 0 or not finite)."""
    b = _mean(before)
    return _mean(after) / b - 1.0 if b and math.isfinite(b) else math.nan


def within_noise(before: Sequence[float], after: Sequence[float]) -> bool:
    """|mean(after) - mean(before)| <= the larger of the two codes' ranges (max - min)."""
    noise = max(max(before) - min(before), max(after) - min(after))
    return abs(_mean(after) - _mean(before)) <= noise


@dataclass
class Shift:
    """One bench row over the runs: its ratios and its figures (value) before and after."""

    section: str
    measure: str
    unit: str
    ratio_before: list[float]
    ratio_after: list[float]
    value_before: list[float]
    value_after: list[float]


def _load(path: str) -> dict:
    try:
        with open(path) as fh:
            doc = json.load(fh)
        return {"rows": {(name, row["measure"]): row for name, sec in doc["sections"].items() for row in sec["rows"]},
                "same": tuple(doc[a][b] for a, b in SAME)}
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise InputError(f"{path}: not a ddfbench.bench JSON file ({type(err).__name__}: {err})") from None


def shifts(before: Sequence[str], after: Sequence[str]) -> tuple[list[Shift], list[str]]:
    """The rows every file holds, and the 'section: measure' names some file lacks. InputError unless
    each side has two runs or more and every file shares device, sizes and threads."""
    if len(before) < 2 or len(after) < 2:
        raise InputError(f"--before {len(before)} / --after {len(after)} files: need two runs of each code "
                         "(one run has no run-to-run noise to compare with)")
    docs = {p: _load(p) for p in [*before, *after]}
    kinds = {d["same"] for d in docs.values()}
    if len(kinds) > 1:
        raise InputError(f"the files differ in {'/'.join(b for _, b in SAME)}: {sorted(map(str, kinds))}")
    runs = [docs[p]["rows"] for p in before], [docs[p]["rows"] for p in after]
    every = set.intersection(*(set(r) for side in runs for r in side))
    some = set.union(*(set(r) for side in runs for r in side))
    out = []
    for key in (k for k in runs[0][0] if k in every):
        pick = lambda side, field: [float(r[key][field]) for r in side]  # noqa: E731
        out.append(Shift(*key, runs[0][0][key]["unit"], pick(runs[0], "ratio"), pick(runs[1], "ratio"),
                         pick(runs[0], "value"), pick(runs[1], "value")))
    return out, sorted(f"{s}: {m}" for s, m in some - every)


def _spread(xs: Sequence[float]) -> str:
    mean = _mean(xs)
    return f"{(max(xs) - min(xs)) / abs(mean):.0%}" if mean else "–"


def _yes(ok: bool) -> str:
    return "yes" if ok else "**no**"


def to_markdown(rows: Sequence[Shift], missing: Sequence[str], before: Sequence[str], after: Sequence[str]) -> str:
    by_ratio = sum(within_noise(r.ratio_before, r.ratio_after) for r in rows)
    by_value = sum(not within_noise(r.ratio_before, r.ratio_after) and within_noise(r.value_before, r.value_after)
                   for r in rows)
    lines = [
        "# Bench before and after",
        "",
        f"before: {', '.join(before)}; after: {', '.join(after)}. ratio: each row's same-process ratio (see the "
        "bench report); figure: the row's own value; noise: (max - min) / mean over one code's runs; change: "
        "mean after / mean before - 1; within noise: the mean moved no more than the larger of the two "
        "codes' ranges.",
        "",
        f"{by_ratio} of {len(rows)} rows within noise by their ratio; {by_value} more by their own figure "
        "(the ratio moved with its reference).",
        "",
        "| section | measure | ratios before | ratios after | ratio noise before / after | ratio change | "
        "ratio within noise | figures before | figures after | figure change | figure within noise |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.section} | {r.measure} | {', '.join(map(number, r.ratio_before))} | "
            f"{', '.join(map(number, r.ratio_after))} | {_spread(r.ratio_before)} / {_spread(r.ratio_after)} | "
            f"{change(r.ratio_before, r.ratio_after):+.0%} | {_yes(within_noise(r.ratio_before, r.ratio_after))} | "
            f"{', '.join(map(number, r.value_before))} {r.unit} | {', '.join(map(number, r.value_after))} {r.unit} | "
            f"{change(r.value_before, r.value_after):+.1%} | {_yes(within_noise(r.value_before, r.value_after))} |")
    if missing:
        lines += ["", "Rows not in every file: " + "; ".join(missing)]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.bench.compare",
                                 description="Bench runs of two codes compared row by row against their noise.")
    ap.add_argument("--before", nargs="+", required=True, help="bench JSON files of the code before")
    ap.add_argument("--after", nargs="+", required=True, help="bench JSON files of the code after")
    ap.add_argument("--out", default=None, help="also write the table to this .md file")
    args = ap.parse_args(argv)
    try:
        rows, missing = shifts(args.before, args.after)
    except InputError as err:
        print(f"ddfbench.bench.compare: {err}", file=sys.stderr)
        return 2
    text = to_markdown(rows, missing, args.before, args.after)
    print(text, end="")
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
