"""The tuning protocol's verdict (+experiment=tune_finalists): each family's candidates on the tuning shapes, the
winner, the winner against the runner-up, and a change of preset confirmed on fresh seeds.

A candidate is a model preset at one of its `tune_finalists` levels (record config `capacity`). Its score is the
geometric mean over the tuning shapes of its mean CD-L2 over seeds (ddfbench.report.across_shapes); a candidate
with a run that gave no result on a shape is not eligible. The winner is the eligible candidate of lowest score;
against the runner-up it is set shape by shape (n = shapes, the honest n for a claim about shapes) and run by run
(n = shape x seed pairs, tighter but treating seeds as replicates). The incumbent (the preset as it is) is kept
unless the winner is separable from its runner-up or the incumbent did not converge on a tuning shape (no result in
any of its runs there): a miss in some runs only does not replace it. Such one-off misses moved the GAN's preset when
they did: trial 15 missed the cow in one of 3 seeds at c020f6c and trial 16 did at dc0a417, each not the other time.

The winner is picked and tested on the same seeds (the experiment's, SELECTION_SEEDS), which leans towards
'separable'. So a separable winner that is not the incumbent replaces it only when confirmed on fresh seeds: the
same shapes, the winner and the incumbent only, seeds the selection did not use (confirmation_sweeps gives the
command; its records go into the same results folder and report). Confirmed: the winner has a result in every fresh
run and its by-shape ratio to the incumbent there lies below 1, or the incumbent gave no result on a shape in any
fresh run (confirmation() has the details). ddf_tuned's b was separable from a on seeds 0-2 at
dc0a417 (0.888x [0.815, 0.968]) and not on seeds 3-5 (0.888x [0.753, 1.05]), so a stays.
"""

from __future__ import annotations

import math
from typing import Any

from omegaconf import OmegaConf

from ddfbench.core.plugins import CONF_DIR
from ddfbench.evaluate.metric_registry import by_name
from ddfbench.report.across_shapes import OverShapes, exponentiated, fmt, geometric, ratio, shape_means
from ddfbench.report.paired import log_ratio
from ddfbench.report.records import Record, no_result, ok_records, shape_name
from ddfbench.report.shape_suite import cells_without_result
from ddfbench.report.tables import pipe_lines

CHAMFER = "chamfer_l2"
INCUMBENT = "a"  # the level that is the preset as the experiments run it (each model YAML keeps its preset as a: {})
EXPERIMENT = "tune_finalists"


def selection_seeds() -> list[int]:
    """The seeds the protocol picks its winners on: conf/experiment/tune_finalists.yaml's sweep (0, 1, 2)."""
    cfg = OmegaConf.load(f"{CONF_DIR}/experiment/{EXPERIMENT}.yaml")
    return [int(s) for s in str(cfg.hydra.sweeper.params.seed).split(",")]


def fresh_seeds(chosen: list[int]) -> list[int]:
    """The confirmation's seeds: as many as the selection's, after them (3, 4, 5)."""
    return [max(chosen) + 1 + i for i in range(len(chosen))]


def seed(rec: Record) -> Any:
    """The record's seed as an int (as the config gave it where it is not one)."""
    value = (rec.get("config") or {}).get("seed")
    try:
        return int(value)
    except (TypeError, ValueError):
        return value


def split_by_seed(records: list[Record]) -> tuple[list[int], list[Record], list[Record]]:
    """(the selection seeds, the records of those seeds, the records of other seeds: the confirmation's)."""
    chosen = selection_seeds()
    return chosen, [r for r in records if seed(r) in chosen], [r for r in records if seed(r) not in chosen]


def selection_records(records: list[Record]) -> list[Record]:
    """The records the candidates are scored on (the report's main table)."""
    return split_by_seed(records)[1]


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


def _runs(records: list[Record], model: str, level: str) -> dict[tuple, float]:
    """{(shape, seed): CD-L2} of a candidate's finished runs."""
    read = by_name()[CHAMFER].read
    return {(shape_name(r), seed(r)): read(r) for r in ok_records(records) if candidate(r) == (model, level)}


def _by_run(records: list[Record], model: str, a: str, b: str) -> OverShapes:
    """CD-L2 ratio a / b paired run by run (shape x seed) with its t interval over runs."""
    return exponentiated(log_ratio(_runs(records, model, a), _runs(records, model, b)))


def verdicts(records: list[Record], rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per model: winner, runner-up, the shape-level and run-level ratio winner / runner-up. Eligible: a candidate
    with a result in every run on every shape any candidate of its model ran. incumbent_eligible: the incumbent ran
    and converged on every such shape (a result in at least one run each), so it may be kept."""
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
                        "incumbent_eligible": kept, "separable": False})
            continue
        win, second = eligible[0], eligible[1]
        by_shape = ratio(win["per_shape"], second["per_shape"])
        out.append({"model": model, "winner": win["level"], "runner_up": second["level"], "incumbent_eligible": kept,
                    "by_shape": by_shape, "by_run": _by_run(records, model, win["level"], second["level"]),
                    "separable": math.isfinite(by_shape.hi) and by_shape.hi < 1})
    return out


def needs_confirmation(verdict: dict[str, Any]) -> bool:
    """Whether the verdict proposes to replace a convergent incumbent by a separable winner."""
    return verdict["separable"] and verdict["winner"] != INCUMBENT and verdict["incumbent_eligible"]


def one_per_run(records: list[Record]) -> list[Record]:
    """One record per (model, level, shape, seed): an ok one before a failed one, else the last finished (records of
    one run under two keys, from a config that changed between launches)."""
    best: dict[tuple, Record] = {}
    for r in sorted(records, key=lambda r: (r.get("status") == "ok", str(r.get("finished") or ""))):
        best[(*candidate(r), shape_name(r), seed(r))] = r
    return list(best.values())


def confirmation(selection: list[Record], fresh: list[Record], verdict: dict[str, Any],
                 chosen: list[int]) -> dict[str, Any]:
    """The winner against the incumbent on the fresh seeds. Their grid (the tuning shapes the model ran x
    fresh_seeds x both levels: runs) and how many of its runs have no record yet (missing: pending while > 0); the
    by-shape and by-run CD-L2 ratio winner / incumbent over the runs that gave a result; the shapes where a winner's
    run gave none or failed (no_result_on) and those where every incumbent's run did (lost_by_incumbent). Confirmed:
    nothing missing, no winner's miss, every shape compared or lost, and the by-shape interval below 1 or a shape
    lost (as in the selection, an incumbent that did not converge on a tuning shape gives way)."""
    model, win = verdict["model"], verdict["winner"]
    shapes = list(dict.fromkeys(shape_name(r) for r in selection if r.get("model") == model))
    seeds = fresh_seeds(chosen)
    mine = one_per_run([r for r in fresh if r.get("model") == model and seed(r) in seeds
                        and candidate(r)[1] in (INCUMBENT, win) and shape_name(r) in shapes])
    missing = 2 * len(shapes) * len(seeds) - len(mine)
    read = by_name()[CHAMFER].read

    def per_shape(level: str) -> dict[str, float]:
        return shape_means((shape_name(r), read(r)) for r in ok_records(mine)
                           if candidate(r)[1] == level and not no_result(r))

    def cells(level: str) -> list[dict[str, Any]]:
        return cells_without_result([r for r in mine if candidate(r)[1] == level])

    misses = sorted(c["shape"] for c in cells(win))
    lost = sorted(c["shape"] for c in cells(INCUMBENT) if c["failed"] == c["seeds"])
    by_shape = ratio(per_shape(win), per_shape(INCUMBENT))
    separable = math.isfinite(by_shape.hi) and by_shape.hi < 1
    return {"seeds": seeds, "shapes": shapes, "runs": 2 * len(shapes) * len(seeds), "missing": missing,
            "records": mine, "by_shape": by_shape, "no_result_on": misses, "lost_by_incumbent": lost,
            "by_run": _by_run([r for r in mine if not no_result(r)], model, win, INCUMBENT),
            "confirmed": (not missing and not misses and by_shape.n + len(lost) == len(shapes)
                          and (separable or bool(lost)))}


def _confirmation_sweep(verdict: dict[str, Any], check: dict[str, Any]) -> list[str]:
    """The overrides of the sweep that confirms a verdict's winner (check: its confirmation)."""
    return [f"+experiment={EXPERIMENT}", f"model={verdict['model']}", f"capacity={INCUMBENT},{verdict['winner']}",
            f"shape={','.join(check['shapes'])}", f"seed={','.join(map(str, check['seeds']))}"]


def protocol(records: list[Record]) -> dict[str, Any]:
    """The protocol on all its records: the selection seeds (chosen), the records of those (selection) and of other
    seeds (fresh), the candidates' rows on the selection, and the verdicts, each that proposes a change of preset
    with its confirmation (key "confirm")."""
    chosen, selection, fresh = split_by_seed(records)
    rows = candidate_rows(selection)
    found = verdicts(selection, rows)
    for v in found:
        if needs_confirmation(v):
            v["confirm"] = confirmation(selection, fresh, v, chosen)
    return {"chosen": chosen, "selection": selection, "fresh": fresh, "rows": rows, "verdicts": found}


def confirmation_sweeps(records: list[Record]) -> list[list[str]]:
    """The overrides of each sweep the protocol still needs: one per model whose confirmation has runs without an ok
    record (python -m ddfbench OVERRIDES ... into the same results folder, which skips the runs done; then the
    report)."""
    return [_confirmation_sweep(v, v["confirm"]) for v in protocol(records)["verdicts"]
            if "confirm" in v and v["confirm"]["missing"]]


def preset_to_use(verdict: dict[str, Any]) -> str:
    """The level the experiments should run: the winner when the incumbent may not be kept (it did not converge on a
    tuning shape, or did not run) or when it is separable from its runner-up and confirmed on fresh seeds (verdict
    key "confirm", from confirmation); else the incumbent ('a (kept)': no change); 'none' when there is neither."""
    win = verdict["winner"]
    if win is not None and (not verdict["incumbent_eligible"] or win == INCUMBENT and verdict["separable"]):
        return win
    if needs_confirmation(verdict):
        check = verdict.get("confirm")
        if check is None or check["missing"]:
            return f"{INCUMBENT} (kept until {win} is confirmed on fresh seeds)"
        return f"{win} (confirmed)" if check["confirmed"] else f"{INCUMBENT} (kept: {win} not confirmed)"
    if verdict["incumbent_eligible"]:
        return f"{INCUMBENT} (kept)"
    return "none (no candidate converged on every tuning shape)"


def sections(records: list[Record]) -> list[str]:
    """The markdown of the candidates' table, the verdicts and the confirmations (records of seeds outside
    selection_seeds are the confirmation's)."""
    run = protocol(records)
    chosen, selection, rows = run["chosen"], run["selection"], run["rows"]
    lines = ["## Candidates on the tuning shapes", "",
             *([f"No record of the selection seeds {', '.join(map(str, chosen))} (conf/experiment/{EXPERIMENT}.yaml): "
                "no candidate is scored.", ""] if not selection else []),
             f"Seeds {', '.join(map(str, chosen))}. score: geometric mean over the tuning shapes of the mean CD-L2 "
             "×10³ over seeds, with the t interval of the mean log over shapes (n: shapes where every run gave a "
             "result). Fixed work: steps as run. The table above holds these seeds' runs; the confirmation's, on "
             "fresh seeds, are in its section.", ""]
    lines += pipe_lines(["model", "level", "score CD-L2 ×10³ [95 %]", "runs", "steps", "a run with no result on"],
                        [[f"{r['model']}", f"{r['level']}", fmt(r["score"], 1e3), f"{r['runs']}", f"{r['steps']:,}",
                          ", ".join(r["no_result_on"]) or "–"] for r in rows])
    lines += ["", "## Winner against runner-up", "",
              "Ratio of CD-L2 winner / runner-up: by shape (geometric mean of per-shape ratios of seed means, t "
              "interval over shapes) and by run (paired shape x seed, t interval over runs). The winner is "
              "separable from the runner-up when the by-shape interval lies below 1. The winner is picked and tested "
              "on the same runs, which leans towards 'separable', so a separable winner that is not the incumbent "
              "(level a, the preset as it was) replaces it only when confirmed on fresh seeds (next section): a "
              "change of preset makes every report of it stale and should rest on more than seed noise. A tie here "
              "is a tie: the incumbent stays. An incumbent with no result in any of its runs on some tuning shape is "
              "not kept: the winner replaces it, separable or not; a miss in some runs only does not replace it "
              "(one-off misses of the GAN's candidates on the cow, at c020f6c and at dc0a417, did not repeat in the "
              "other run).",
              ""]
    verdicts = []
    for v in run["verdicts"]:
        if v["runner_up"] is None:
            winner = v["winner"] or "no candidate had a result in every run"
            verdicts.append([f"{v['model']}", f"{winner}", "–", "–", "–", "–", f"{preset_to_use(v)}"])
            continue
        verdicts.append([f"{v['model']}", f"{v['winner']}", f"{v['runner_up']}", f"{fmt(v['by_shape'])}",
                         f"{fmt(v['by_run'])}", "yes" if v["separable"] else "no", f"{preset_to_use(v)}"])
    lines += pipe_lines(["model", "winner", "runner-up", "by shape [95 %]", "by run [95 %]", "separable",
                         "preset to use"], verdicts)
    checks = [v for v in run["verdicts"] if "confirm" in v]
    if checks:
        lines += ["", "## Confirmation on fresh seeds", "",
                  "Each separable winner that would replace the incumbent, against the incumbent on the tuning shapes "
                  "with seeds the selection did not use: CD-L2 ratio winner / incumbent by shape and by run, over the "
                  "runs that gave a result. Confirmed when every run of that grid has a record, the winner has a "
                  "result in each of its runs and the by-shape interval over the other shapes lies below 1 or the "
                  "incumbent gave no result on a shape in any of its runs there (as in the selection, it then gives "
                  "way); pending while runs are missing (the command runs them).", ""]
        confirmations = []
        for v in checks:
            c = v["confirm"]
            seeds = ", ".join(map(str, c["seeds"]))
            if c["missing"]:
                command = " ".join(["python -m ddfbench", *_confirmation_sweep(v, c)])
                confirmations.append([f"{v['model']}", f"{v['winner']} / {INCUMBENT}", seeds,
                                      f"pending: {c['missing']} of {c['runs']} runs without a record: `{command}`",
                                      "–", "–", "–"])
                continue
            confirmations.append([f"{v['model']}", f"{v['winner']} / {INCUMBENT}", seeds, f"{fmt(c['by_shape'])}",
                                  f"{fmt(c['by_run'])}", ", ".join(c["no_result_on"]) or "–",
                                  "yes" if c["confirmed"] else "no"])
        lines += pipe_lines(["model", "winner / incumbent", "seeds", "by shape [95 %]", "by run [95 %]",
                             "winner's run with no result on", "confirmed"], confirmations)
        lines += ["", "The confirmation's runs (CD-L2 ×10³: mean over the runs with a result):", ""]
        confirmation_runs = []
        read = by_name()[CHAMFER].read
        for v in checks:
            for level in (INCUMBENT, v["winner"]):
                for shape in v["confirm"]["shapes"]:
                    runs = sorted((r for r in v["confirm"]["records"]
                                   if candidate(r)[1] == level and shape_name(r) == shape), key=seed)
                    if not runs:
                        continue
                    kept = shape_means((shape, read(r)) for r in ok_records(runs) if not no_result(r)).get(shape)
                    confirmation_runs.append([f"{v['model']}", f"{level}", f"{shape}",
                                              ", ".join(str(seed(r)) for r in runs),
                                              "–" if kept is None else f"{kept * 1e3:.3g}",
                                              f"{sum(r.get('status') != 'ok' or no_result(r) for r in runs)}",
                                              " ".join(str(r.get("key")) for r in runs)])
        lines += pipe_lines(["model", "level", "shape", "seeds", "CD-L2 ×10³", "no result", "record keys"],
                            confirmation_runs)
    used = {id(r) for v in checks for r in v["confirm"]["records"]}
    other = [r for r in run["fresh"] if id(r) not in used]
    if other:
        seeds = sorted({seed(r) for r in other}, key=lambda x: (not isinstance(x, int), x if isinstance(x, int) else 0,
                                                              str(x)))  # 3 before 10
        models = ", ".join(sorted({str(r.get("model")) for r in other}))
        lines += ["", f"{len(other)} runs of seeds outside the selection belong to no confirmation (models: {models}; "
                      f"seeds {', '.join(map(str, seeds))}): in runs.csv and the records, in no table here."]
    return ["\n".join(lines) + "\n"]
