"""python -m ddfbench.bench.compare --before A.json [A2.json ...] --after B.json [B2.json ...] [--out F.md]

Did a change move the benchmark? Bench JSON files of the code before and after (at least two runs of
each, interleaved on one idle host) are compared row by row on their same-process ratios: the
run-to-run noise of a row is the range of its ratio over the runs of one code, and a row is "within
noise" when the change of its mean ratio is no larger than the larger of the two codes' ranges: the
code moved it no more than running the same code again did. (Overlapping ranges would be too strict a
test: two runs of each code, all four from one distribution, fail to overlap one time in three.)
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from typing import Sequence

from ddfbench.bench.table import number
from ddfbench.errors import InputError


@dataclass
class Shift:
    """One bench row over the runs: its ratios before and after, and what that says."""

    section: str
    measure: str
    before: list[float]
    after: list[float]

    @staticmethod
    def _mean(xs: Sequence[float]) -> float:
        return sum(xs) / len(xs)

    @staticmethod
    def spread(xs: Sequence[float]) -> float:
        """(max - min) / mean of one code's ratios: its run-to-run noise (0 for a single run)."""
        mean = sum(xs) / len(xs)
        return (max(xs) - min(xs)) / abs(mean) if mean else 0.0

    @property
    def change(self) -> float:
        """mean(after) / mean(before) - 1."""
        return self._mean(self.after) / self._mean(self.before) - 1.0

    @property
    def within_noise(self) -> bool:
        """|mean after - mean before| <= the larger of the two codes' ratio ranges (max - min)."""
        noise = max(max(self.before) - min(self.before), max(self.after) - min(self.after))
        return abs(self._mean(self.after) - self._mean(self.before)) <= noise


def ratios(path: str) -> dict[tuple[str, str], float]:
    """{(section, measure): ratio} of one bench JSON file; InputError naming the file when it is not one."""
    try:
        with open(path) as fh:
            doc = json.load(fh)
        sections = doc["sections"]
        return {(name, row["measure"]): float(row["ratio"])
                for name, sec in sections.items() for row in sec["rows"]}
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise InputError(f"{path}: not a ddfbench.bench JSON file ({type(err).__name__}: {err})") from None


def shifts(before: Sequence[str], after: Sequence[str]) -> tuple[list[Shift], list[str]]:
    """The rows every file holds, and the 'section: measure' names some file lacks."""
    runs_b, runs_a = [ratios(p) for p in before], [ratios(p) for p in after]
    runs = runs_b + runs_a
    every = set.intersection(*(set(r) for r in runs))
    some = set.union(*(set(r) for r in runs))
    ordered = [key for key in runs_b[0] if key in every]
    rows = [Shift(s, m, [r[(s, m)] for r in runs_b], [r[(s, m)] for r in runs_a]) for s, m in ordered]
    return rows, sorted(f"{s}: {m}" for s, m in some - every)


def to_markdown(rows: Sequence[Shift], missing: Sequence[str], before: Sequence[str], after: Sequence[str]) -> str:
    n_out = sum(not r.within_noise for r in rows)
    lines = [
        "# Bench before and after",
        "",
        f"before: {', '.join(before)}; after: {', '.join(after)}. Ratios are each row's same-process ratio "
        "(see the bench report); noise = (max - min) / mean over one code's runs; change = mean after / mean "
        "before - 1; within noise = the mean moved no more than the larger of the two codes' ranges.",
        "",
        f"{len(rows) - n_out} of {len(rows)} rows within noise.",
        "",
        "| section | measure | ratios before | ratios after | noise before | noise after | change | within noise |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.section} | {r.measure} | {', '.join(number(x) for x in r.before)} | "
            f"{', '.join(number(x) for x in r.after)} | {Shift.spread(r.before):.0%} | {Shift.spread(r.after):.0%} | "
            f"{r.change:+.0%} | {'yes' if r.within_noise else '**no**'} |")
    if missing:
        lines += ["", "Rows not in every file: " + "; ".join(missing)]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.bench.compare", description=__doc__.splitlines()[0])
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
