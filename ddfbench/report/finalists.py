"""The tuning protocol's verdict (+experiment=tune_finalists): each family's candidates on the tuning shapes, the
winner, and the winner against the runner-up.

A candidate is a model preset at one of its `tune_finalists` levels (record config `capacity`). Its score is the
geometric mean over the tuning shapes of its mean CD-L2 over seeds (ddfbench.report.across_shapes); a candidate
with a run that gave no result on a shape is not eligible. The winner is the eligible candidate of lowest score;
against the runner-up it is set shape by shape (n = shapes, the honest n for a claim about shapes) and run by run
(n = shape x seed pairs, tighter but treating seeds as replicates). The incumbent (the preset as it is) is kept
unless the winner is separable from its runner-up or the incumbent did not converge on a tuning shape (no result in
any of its runs there): a miss in some runs only does not replace it. Such one-off misses moved the GAN's preset when
they did: trial 15 missed the cow in one of 3 seeds at c020f6c and trial 16 did at dc0a417, each not the other time.
"""

from __future__ import annotations

import math
from typing import Any

from ddfbench.evaluate.metric_registry import by_name
from ddfbench.report.across_shapes import OverShapes, fmt, geometric, ratio, shape_means
from ddfbench.report.paired import log_ratio
from ddfbench.report.records import Record, ok_records, shape_name
from ddfbench.report.shape_suite import cells_without_result

CHAMFER = "chamfer_l2"
INCUMBENT = "a"  # the level that is the preset as the experiments run it (each model YAML keeps its preset as a: {})


def candidate(rec: Record) -> tuple[str, str]:
    """(model, level) of a record."""
    return str(rec.get("model")), str((rec.get("config") or {}).get("capacity"))


def candidate_rows(records: list[Record]) -> list[dict[str, Any]]:
    """Per (model, level): shapes run, the shapes with a run that gave no result or failed (no_result_on), those
    where every run did (not_converged_on), the score over the other shapes, the steps (the largest of its runs)."""
    read = by_name()[CHAMFER].read
    rows = []
    for model, level in sorted(dict.fromkeys(candidate(r) for r in records)):
        mine = [r for r in records if candidate(r) == (model, level)]
        cells = cells_without_result(mine)  # one model and level: a cell a shape
        failed = sorted(c["shape"] for c in cells)
        not_converged = sorted(c["shape"] for c in cells if c["failed"] == c["seeds"])
        mine = ok_records(mine)
        per_shape = shape_means((shape_name(r), read(r)) for r in mine if shape_name(r) not in failed)
        rows.append({"model": model, "level": level, "shapes": len({shape_name(r) for r in mine}),
                     "no_result_on": failed, "not_converged_on": not_converged, "per_shape": per_shape,
                     "score": geometric(per_shape),
                     "runs": len(mine), "steps": max((int((r.get("fit") or {}).get("steps") or 0) for r in mine),
                                                     default=0)})
    return rows


def verdicts(records: list[Record], rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per model: winner, runner-up, the shape-level and run-level ratio winner / runner-up. Eligible: a candidate
    with a result in every run on every shape any candidate of its model ran. incumbent_eligible: the incumbent ran
    and converged on every such shape (a result in at least one run each), so it may be kept."""
    read = by_name()[CHAMFER].read
    out = []
    for model in dict.fromkeys(r["model"] for r in rows):
        shapes = max(r["shapes"] for r in rows if r["model"] == model)
        eligible = sorted((r for r in rows if r["model"] == model and not r["no_result_on"]
                           and r["score"].n == shapes and math.isfinite(r["score"].center)),
                          key=lambda r: r["score"].center)
        incumbent = [r for r in rows if r["model"] == model and r["level"] == INCUMBENT]
        kept = bool(incumbent) and incumbent[0]["shapes"] == shapes and not incumbent[0]["not_converged_on"]
        if len(eligible) < 2:
            out.append({"model": model, "winner": eligible[0]["level"] if eligible else None, "runner_up": None,
                        "incumbent_eligible": kept})
            continue
        win, second = eligible[0], eligible[1]

        def runs_of(level: str) -> dict[tuple, float]:
            return {(shape_name(r), (r.get("config") or {}).get("seed")): read(r)
                    for r in ok_records(records) if candidate(r) == (model, level)}

        by_run = log_ratio(runs_of(win["level"]), runs_of(second["level"]))
        out.append({"model": model, "winner": win["level"], "runner_up": second["level"], "incumbent_eligible": kept,
                    "by_shape": ratio(win["per_shape"], second["per_shape"]),
                    "by_run": OverShapes(math.exp(by_run.mean), math.exp(by_run.lo), math.exp(by_run.hi), by_run.n)})
    return out


def preset_to_use(verdict: dict[str, Any], separable: bool) -> str:
    """The level the experiments should run: the winner when separable from its runner-up or when the incumbent may
    not be kept (it did not converge on a tuning shape, or did not run), else the incumbent ('a (kept)': no change);
    'none' when there is neither."""
    if verdict["winner"] is not None and (separable or not verdict["incumbent_eligible"]):
        return verdict["winner"]
    if verdict["incumbent_eligible"]:
        return f"{INCUMBENT} (kept)"
    return "none (no candidate converged on every tuning shape)"


def sections(records: list[Record]) -> list[str]:
    """The markdown of the candidates' table and the verdicts."""
    rows = candidate_rows(records)
    lines = ["## Candidates on the tuning shapes", "",
             "score: geometric mean over the tuning shapes of the mean CD-L2 ×10³ over seeds, with the t interval of "
             "the mean log over shapes (n: shapes where every run gave a result). Fixed work: steps as run.", "",
             "| model | level | score CD-L2 ×10³ [95 %] | runs | steps | a run with no result on |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['model']} | {r['level']} | {fmt(r['score'], 1e3)} | {r['runs']} | {r['steps']:,} | "
              f"{', '.join(r['no_result_on']) or '–'} |" for r in rows]
    lines += ["", "## Winner against runner-up", "",
              "Ratio of CD-L2 winner / runner-up: by shape (geometric mean of per-shape ratios of seed means, t "
              "interval over shapes) and by run (paired shape x seed, t interval over runs). The winner is "
              "separable from the runner-up when the by-shape interval lies below 1. The winner is picked and tested "
              "on the same runs, which leans towards 'separable'; a tie here is a tie. The preset the experiments use: "
              "the winner when it is separable, else the incumbent (level a, the preset as it was), so that a change "
              "of preset, which makes every report of it stale, rests on more than seed noise. An incumbent with no "
              "result in any of its runs on some tuning shape is not kept: the winner replaces it, separable or not; a "
              "miss in some runs only does not replace it (one-off misses of the GAN's candidates on the cow, at "
              "c020f6c and at dc0a417, did not repeat in the other run).",
              "",
              "| model | winner | runner-up | by shape [95 %] | by run [95 %] | separable | preset to use |",
              "|---|---|---|---|---|---|---|"]
    for v in verdicts(records, rows):
        if v["runner_up"] is None:
            winner = v["winner"] or "no candidate had a result in every run"
            lines.append(f"| {v['model']} | {winner} | – | – | – | – | "
                         f"{preset_to_use(v, separable=False)} |")
            continue
        separable = math.isfinite(v["by_shape"].hi) and v["by_shape"].hi < 1
        use = preset_to_use(v, separable)
        lines.append(f"| {v['model']} | {v['winner']} | {v['runner_up']} | {fmt(v['by_shape'])} | "
                     f"{fmt(v['by_run'])} | {'yes' if separable else 'no'} | {use} |")
    return ["\n".join(lines) + "\n"]
