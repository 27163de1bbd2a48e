"""The shape suite's and the tuning protocol's report sections on synthetic records whose answers are known."""

import math
import os

import pandas as pd
import pytest

from ddfbench.report import compact, finalists, shape_suite, suite
from ddfbench.report.across_shapes import ratio


def rec(model, shape, seed, chamfer, level=None, empty=False, fscore=0.5, steps=100):
    return {"status": "ok", "model": model, "family": model, "experiment": "shape_suite", "key": f"{model}{shape}{seed}{level}",
            "shape": {"name": shape}, "config": {"seed": seed, "capacity": level, "eval": {"n_points": 1000}},
            "metrics": {"chamfer_l2": chamfer, "fscore": {"0.01": fscore, "0.02": 0.0 if empty else 0.9},
                        "empty_reconstruction": empty},
            "cost": {"fit_s": 2.0, "storage_bytes": 1000}, "fit": {"steps": steps, "epochs": 1.0}}


SHAPES = [f"s{g}" for g in range(6)]


@pytest.fixture
def tags(tmp_path):
    df = pd.DataFrame({"shape": SHAPES, "split": "evaluation", "kind": "x", "faces": 10,
                       "thinnest": [0.5, 0.4, 0.3, 0.2, 0.1, None], "genus": range(6), "sharp_edges": 0.0,
                       "detail": 1.0, "open_boundary": 0.0, "components": 1, "provenance": "p", "license": "l"})
    df.to_csv(tmp_path / shape_suite.TAGS_FILE, index=False)
    return df


def suite_records():
    out = []
    for g, shape in enumerate(SHAPES):
        for seed in (0, 1):
            jitter = 1.1 if seed else 1 / 1.1  # seeds around the shape's value: its seed mean is not its value
            out.append(rec("a", shape, seed, 1e-3 * 2**g * jitter))
            out.append(rec("b", shape, seed, 1e-3 * 2**g * (2 if g % 2 else 4)))
    out.append(rec("c", "s0", 0, 1.0, empty=True))
    out.append(rec("c", "s1", 0, 1e-3))
    return out


def test_per_shape_means_then_geometric_over_shapes_and_ratios_over_shared_shapes(tags):
    records = suite_records()
    cells = shape_suite.cells(records, "chamfer_l2")
    assert cells["a"]["s3"] == pytest.approx(8e-3 * (1.1 + 1 / 1.1) / 2)
    assert set(cells["c"]) == {"s1"}  # the empty run's shape is left out
    got = ratio(cells["a"], cells["b"])
    # per shape a / b = mean(1.1, 1/1.1) / (4 or 2): geometric mean over 3 shapes of each
    expected = (1.1 + 1 / 1.1) / 2 / math.sqrt(8)
    assert got.center == pytest.approx(expected) and got.n == 6
    assert shape_suite.cells_without_result(records) == [{"model": "c", "shape": "s0", "failed": 1, "seeds": 1,
                                                   "steps": 100, "epochs": 1.0}]


def test_axis_rows_rank_and_split_at_the_median(tags):
    rows = {(r["model"], r["axis"]): r for r in shape_suite.axis_rows(suite_records(), tags)}
    genus = rows[("a", "genus")]
    assert genus["n"] == 6 and genus["rho"] == pytest.approx(1.0)
    # harder half genus 3, 4, 5 over easier half 0, 1, 2: 2^(3) in the geometric mean
    assert genus["ratio"] == pytest.approx(8.0) and genus["lo"] < 8.0 < genus["hi"]
    thin = rows[("a", "thinnest")]
    assert thin["n"] == 5 and thin["rho"] == pytest.approx(-1.0)  # the open shape has no thickness
    # thinner is harder: below the median 0.3 are s3, s4 (genus 3, 4), the rest s0-s2: 2^(3.5 - 1)
    assert thin["ratio"] == pytest.approx(2**2.5)
    assert all(r["p_holm"] >= r["p"] for r in rows.values() if math.isfinite(r["p"]))


def test_sections_write_the_tables_and_the_plot(tags, tmp_path):
    text = "\n".join(shape_suite.sections(suite_records(), str(tmp_path)))
    assert "Holm-corrected across the rows" in text and "| c | s0 | 1 of 1 | 100 | 1 |" in text
    assert (tmp_path / "by_axis.png").stat().st_size > 10000 and (tmp_path / "by_axis.csv").exists()


def test_a_cell_is_not_converged_only_when_every_seed_gave_no_result(tags):
    records = [*suite_records(), rec("c", "s2", 0, 1.0, empty=True), rec("c", "s2", 1, 2e-3)]
    per_shape = {line.split(" | ")[0].strip("| "): line.split(" | ")[-1].strip(" |")
                 for line in shape_suite.per_shape_markdown(records, tags).splitlines()[2:]}
    # s0: c's only seed was empty; s2: one of two seeds empty, the other a surface; s1: c's only seed a surface
    assert (per_shape["s0"], per_shape["s2"], per_shape["s1"]) == ("not converged", "no result in 1 of 2", "1")


def finalist_records():
    out = []
    for shape_i, shape in enumerate(("cow", "torus", "gear")):
        for seed in (0, 1, 2):
            out.append(rec("m", shape, seed, 1e-3 * (1 + shape_i) * (1 + 0.1 * seed), level="a"))
            out.append(rec("m", shape, seed, 2e-3 * (1 + shape_i) * (1 + 0.05 * seed), level="b"))
            # lowest chamfer of all, but empty on the gear: not eligible
            out.append(rec("m", shape, seed, 1e-4, level="c", empty=shape == "gear" and seed == 1))
    return out


def test_the_winner_is_the_lowest_eligible_candidate_and_is_set_against_the_runner_up():
    records = finalist_records()
    rows = finalists.candidate_rows(records)
    c = next(r for r in rows if r["level"] == "c")
    assert c["no_result_on"] == ["gear"] and c["score"].n == 2
    (verdict,) = finalists.verdicts(records, rows)
    assert (verdict["winner"], verdict["runner_up"]) == ("a", "b")
    # per shape a / b = mean(1, 1.1, 1.2) / (2 mean(1, 1.05, 1.1)) = 1.1 / 2.1, the same on every shape
    assert verdict["by_shape"].center == pytest.approx(1.1 / 2.1) and verdict["by_shape"].n == 3
    assert verdict["by_shape"].hi == pytest.approx(1.1 / 2.1)  # the same ratio on every shape: no spread
    assert verdict["by_run"].n == 9 and verdict["by_run"].hi < 1
    assert "| m | a | b |" in finalists.sections(records)[0] and "| yes | a |" in finalists.sections(records)[0]


def test_an_incumbent_that_did_not_converge_on_a_tuning_shape_gives_way_but_a_one_off_miss_does_not():
    def candidates(a_empty_seeds):
        out = []
        for shape_i, shape in enumerate(("cow", "torus", "gear")):
            for seed in (0, 1, 2):
                # a: lowest chamfer but empty on the cow in a_empty_seeds; b and c tied within noise, b just lower
                out.append(rec("m", shape, seed, 1e-4, level="a", empty=shape == "cow" and seed in a_empty_seeds))
                out.append(rec("m", shape, seed, 1e-3 * (1 + shape_i) * (1 + 0.1 * seed), level="b"))
                out.append(rec("m", shape, seed, 1e-3 * (1 + shape_i) * (1 + 0.1 * ((seed + 1) % 3)), level="c"))
        return out

    records = candidates({0, 1, 2})  # no result on the cow in any seed: not converged there
    rows = finalists.candidate_rows(records)
    assert next(r for r in rows if r["level"] == "a")["not_converged_on"] == ["cow"]
    (verdict,) = finalists.verdicts(records, rows)
    assert verdict["winner"] in ("b", "c") and not verdict["incumbent_eligible"]
    text = finalists.sections(records)[0]
    assert f"| no | {verdict['winner']} |" in text and "(kept)" not in text.split("## Winner against runner-up")[1]
    for misses in ({0}, {0, 2}):  # some seeds only, even most: misses that need not repeat, so a is kept
        records = candidates(misses)
        rows = finalists.candidate_rows(records)
        a = next(r for r in rows if r["level"] == "a")
        assert a["no_result_on"] == ["cow"] and a["not_converged_on"] == []
        (verdict,) = finalists.verdicts(records, rows)
        assert verdict["winner"] in ("b", "c") and verdict["incumbent_eligible"]
        assert "| no | a (kept) |" in finalists.sections(records)[0]
    crashed = [{**r, "status": "failed"} if r["config"]["capacity"] == "a" and r["shape"]["name"] == "cow" else r
               for r in candidates(set())]  # a crashed on the cow in every seed: not converged there either
    (verdict,) = finalists.verdicts(crashed, finalists.candidate_rows(crashed))
    assert not verdict["incumbent_eligible"]
    alone = [r for r in candidates({0, 1, 2}) if r["config"]["capacity"] == "a"]  # no winner, and a may not be kept
    assert "| – | none (no candidate converged on every tuning shape) |" in finalists.sections(alone)[0]
    no_incumbent = [r for r in candidates(set()) if r["config"]["capacity"] != "a"]
    (verdict,) = finalists.verdicts(no_incumbent, finalists.candidate_rows(no_incumbent))
    assert not verdict["incumbent_eligible"]
    assert f"| no | {verdict['winner']} |" in finalists.sections(no_incumbent)[0]
    # a converged everywhere, 1 % behind b (within the seeds' spread): b wins, not separably, and a is kept
    shapes = {"cow": 0, "torus": 1, "gear": 2}
    fixed = [rec("m", r["shape"]["name"], r["config"]["seed"], 1.01e-3 * (1 + shapes[r["shape"]["name"]])
                 * (1 + 0.1 * ((r["config"]["seed"] + 2) % 3)) * (1 + 0.05 * shapes[r["shape"]["name"]] ** 2),
                 level="a") if r["config"]["capacity"] == "a" else r for r in records]
    (tie,) = finalists.verdicts(fixed, finalists.candidate_rows(fixed))
    assert tie["winner"] != "a" and tie["incumbent_eligible"] and tie["by_shape"].hi >= 1
    assert f"| {tie['winner']} | " in finalists.sections(fixed)[0] and "| no | a (kept) |" in finalists.sections(fixed)[0]


def separable_b(fresh_seeds=(), b_factor=0.8, b_empty_on=None, a_empty_in=None, fresh_shapes=None):
    """Level b 0.8x level a on every shape in seeds 0-2 (separable), with a and b run again on fresh_seeds (on
    fresh_shapes, default all), where b is b_factor x a (its seed spread as in 0-2), b is empty on shape b_empty_on
    in its first fresh seed and a is empty on every shape in seed a_empty_in."""
    out = []
    for shape_i, shape in enumerate(("cow", "torus", "gear", "open_box")):
        for seed in (0, 1, 2, *fresh_seeds):
            if seed > 2 and fresh_shapes is not None and shape not in fresh_shapes:
                continue
            factor = 0.8 if seed < 3 else b_factor
            spread = 1 + 0.1 * (seed % 3) + 0.02 * shape_i  # b's spread differs from a's: the ratios vary a little
            a_value = 1.0 if seed == a_empty_in else 1e-3 * (1 + shape_i) * (1 + 0.1 * (seed % 3))  # empty: the penalty
            out.append(rec("m", shape, seed, a_value, level="a", empty=seed == a_empty_in))
            out.append(rec("m", shape, seed, factor * 1e-3 * (1 + shape_i) * spread, level="b",
                           empty=shape == b_empty_on and seed == fresh_seeds[0]))
            if seed < 3:
                out.append(rec("m", shape, seed, 2e-3 * (1 + shape_i), level="c"))
    return out


SWEEP = ["+experiment=tune_finalists", "model=m", "capacity=a,b", "shape=cow,torus,gear,open_box", "seed=3,4,5"]


def test_a_separable_winner_replaces_the_incumbent_only_when_confirmed_on_fresh_seeds():
    # selection seeds 0-2 only: b is separable from a but not yet confirmed; the sweep that would confirm it
    records = separable_b()
    assert finalists.selection_seeds() == [0, 1, 2]
    (verdict,) = finalists.verdicts(records, finalists.candidate_rows(records))
    assert (verdict["winner"], verdict["runner_up"], verdict["separable"]) == ("b", "a", True)
    assert finalists.confirmation_sweeps(records) == [SWEEP]
    text = finalists.sections(records)[0]
    assert "| yes | a (kept until b is confirmed on fresh seeds) |" in text
    assert f"| m | b / a | 3, 4, 5 | pending: 24 of 24 runs without a record: `python -m ddfbench {' '.join(SWEEP)}`" \
        in text
    # b again 0.8x a on seeds 3-5: confirmed, and the fresh seeds do not enter the selection's table
    records = separable_b(fresh_seeds=(3, 4, 5))
    assert finalists.confirmation_sweeps(records) == []
    text = finalists.sections(records)[0]
    assert "| yes | b (confirmed) |" in text and "| m | b / a | 3, 4, 5 | 0.8" in text and "| – | yes |" in text
    assert "| m | a | " in text and " | 12 | 100 | – |" in text  # 4 shapes x seeds 0-2, not 24 runs
    assert "| m | b | gear | 3, 4, 5 | " in text  # the confirmation's runs, listed
    # b level with a on seeds 3-5 (a selection that was seed noise), or empty in one fresh run: a is kept
    for fresh in (separable_b(fresh_seeds=(3, 4, 5), b_factor=1.0),
                  separable_b(fresh_seeds=(3, 4, 5), b_empty_on="gear")):
        text = finalists.sections(fresh)[0]
        assert "| yes | a (kept: b not confirmed) |" in text and "| no |" in text.split("## Confirmation")[1]
    assert "| gear | no |" in finalists.sections(separable_b(fresh_seeds=(3, 4, 5), b_empty_on="gear"))[0]


def test_a_confirmation_cut_short_stays_pending_and_an_incumbent_s_miss_is_no_win():
    # one fresh seed of three, or two shapes of four: pending, and the sweep is asked for again (Hydra skips the done)
    for part in (separable_b(fresh_seeds=(3,)), separable_b(fresh_seeds=(3, 4, 5), fresh_shapes=("cow", "gear"))):
        assert finalists.confirmation_sweeps(part) == [SWEEP]
        text = finalists.sections(part)[0]
        assert "| yes | a (kept until b is confirmed on fresh seeds) |" in text and "| pending: " in text
    assert "| pending: 16 of 24 runs without a record" in finalists.sections(separable_b(fresh_seeds=(3,)))[0]
    # b level with a, and a empty in seed 3 on every shape: a's misses are left out, not counted as b's wins
    text = finalists.sections(separable_b(fresh_seeds=(3, 4, 5), b_factor=1.0, a_empty_in=3))[0]
    assert "| yes | a (kept: b not confirmed) |" in text
    # a winner's run that failed (a divergence fails again on every rerun): not pending, not confirmed, listed
    failed = [{**r, "status": "failed"} if (r["config"]["capacity"], r["shape"]["name"], r["config"]["seed"])
              == ("b", "gear", 3) else r for r in separable_b(fresh_seeds=(3, 4, 5))]
    assert finalists.confirmation_sweeps(failed) == []
    text = finalists.sections(failed)[0]
    assert "| yes | a (kept: b not confirmed) |" in text and "| m | b | gear | 3, 4, 5 | " in text
    assert "| gear | no |" in text and "| pending: " not in text
    # the preset with no result on the gear in every fresh seed: that shape counts for the winner, as in the selection
    lost = [{**r, "metrics": {**r["metrics"], "chamfer_l2": 1.0, "empty_reconstruction": True}}
            if r["config"]["capacity"] == "a" and r["shape"]["name"] == "gear" and r["config"]["seed"] > 2 else r
            for r in separable_b(fresh_seeds=(3, 4, 5))]
    assert "| yes | b (confirmed) |" in finalists.sections(lost)[0]
    tied_but_lost = [{**r, "metrics": {**r["metrics"], "chamfer_l2": 1.0, "empty_reconstruction": True}}
                     if r["config"]["capacity"] == "a" and r["shape"]["name"] == "gear" and r["config"]["seed"] > 2
                     else r for r in separable_b(fresh_seeds=(3, 4, 5), b_factor=1.0)]
    assert "| yes | b (confirmed) |" in finalists.sections(tied_but_lost)[0]  # tied elsewhere: the lost shape decides
    # a stale failed record of a run beside its ok one (a key that changed between launches): the ok one counts
    stale = separable_b(fresh_seeds=(3, 4, 5))
    stale += [{**r, "key": "old", "status": "failed", "finished": "0"} for r in stale
              if (r["config"]["capacity"], r["shape"]["name"], r["config"]["seed"]) == ("b", "gear", 3)]
    assert "| yes | b (confirmed) |" in finalists.sections(stale)[0]
    # a chamfer missing from the preset's gear runs (not a miss): the gear is not compared, so not confirmed
    unread = [{**r, "metrics": {k: v for k, v in r["metrics"].items() if k != "chamfer_l2"}}
              if r["config"]["capacity"] == "a" and r["shape"]["name"] == "gear" and r["config"]["seed"] > 2 else r
              for r in separable_b(fresh_seeds=(3, 4, 5))]
    assert "| yes | a (kept: b not confirmed) |" in finalists.sections(unread)[0]
    # seeds stored as strings are the same seeds
    as_text = [{**r, "config": {**r["config"], "seed": str(r["config"]["seed"])}} for r in separable_b()]
    assert finalists.confirmation_sweeps(as_text) == [SWEEP]
    other = separable_b(fresh_seeds=(3, 4, 5)) + [rec("g", "cow", s, 1e-3, level=lv) for s, lv in ((7, "a"), (8, "b"))]
    assert "2 runs of seeds outside the selection belong to no confirmation (models: g; seeds 7, 8)" in \
        finalists.sections(other)[0]
    fresh_only = [r for r in separable_b(fresh_seeds=(3, 4, 5)) if r["config"]["seed"] > 2]
    assert "No record of the selection seeds 0, 1, 2" in finalists.sections(fresh_only)[0]


def test_the_committed_protocol_run_needed_exactly_the_confirmation_that_was_run():
    """reports/tune_finalists: without its fresh seeds, the protocol asks for ddf_tuned a and b on seeds 3-5, the sweep
    that was run (reports/tune_finalists_confirm until 5ff6001); with them nothing is pending and b is not confirmed."""
    committed = compact.read_compact(os.path.join(suite.ROOT, "reports", "tune_finalists", compact.FILE))
    selection = [r for r in committed if r["config"]["seed"] in (0, 1, 2)]
    (sweep,) = finalists.confirmation_sweeps(selection)
    assert sweep[1:3] == ["model=ddf_tuned", "capacity=a,b"]
    assert sweep[-1] == "seed=3,4,5"
    jobs = suite.expand(suite.Entry("tune_finalists", "reports/tune_finalists", sweep[1:])).per_model()
    assert jobs == {"ddf_tuned": 2 * 4 * 3}
    assert finalists.confirmation_sweeps(committed) == []
    assert "| ddf_tuned | b / a | 3, 4, 5 |" in finalists.sections(committed)[0]


def test_the_ddf_sdf_claim_over_shapes_is_refuted_far_from_one_and_confirmed_near_it():
    from ddfbench.report import claims

    def records(factor):
        out = []
        for i, shape in enumerate(SHAPES):
            for seed in (0, 1):
                base = 1e-4 * (i + 1)
                out.append(rec("neural_sdf_tuned", shape, seed, base))
                out.append(rec("ddf_tuned", shape, seed, base * factor * (1.0 + 0.1 * (i % 3))))
        return {"shape_suite": out}

    (far,) = claims.accurate_as_sdf_over_shapes(records(20.0))
    assert far.verdict == claims.REFUTED and "n=6 shapes" in far.measured
    (near,) = claims.accurate_as_sdf_over_shapes(records(1.0))
    assert near.verdict == claims.CONFIRMED
    (none,) = claims.accurate_as_sdf_over_shapes({"shape_suite": []})
    assert none.verdict == claims.NO_RECORDS



def test_a_refutation_at_the_equivalence_bound_is_holm_tested_at_that_bound_not_at_one():
    """DDF/SDF above 1.5 on every shape, its unadjusted interval above 1.5 and its p against 1 far below 0.05 after
    Holm, but its p against 1.5 (the claim's bound) not: not separable (as reports/shape_suite at dc0a417: 6.05x
    [1.62, 22.6], Holm p 0.036 against 1 but 0.12 against 1.5)."""
    import numpy as np
    import scipy.stats

    from ddfbench.report import claims
    from ddfbench.report.across_shapes import ratio_p
    from ddfbench.report.stats import holm

    logs = np.log(1.5) + np.array([0.05, 0.6, 0.1, 0.3, 0.12, 0.5])
    grid = [0.5, 3.0, 0.6, 2.5, 0.7, 2.0]  # the grid SDF: the family's other two ratios far from separable
    out = []
    for i, shape in enumerate(SHAPES):
        out += [rec("neural_sdf_tuned", shape, 0, 1e-4), rec("ddf_tuned", shape, 0, 1e-4 * float(np.exp(logs[i]))),
                rec("grid_sdf", shape, 0, 1e-4 * grid[i])]
    lo = np.exp(logs.mean() - scipy.stats.t.ppf(0.975, 5) * logs.std(ddof=1) / np.sqrt(6))
    assert lo > 1.5  # the unadjusted interval alone would refute
    p1, p_bound = scipy.stats.ttest_1samp(logs, 0.0).pvalue, scipy.stats.ttest_1samp(logs, np.log(1.5)).pvalue
    others = [scipy.stats.ttest_1samp(logs - np.log(grid), 0.0).pvalue, scipy.stats.ttest_1samp(-np.log(grid), 0.0).pvalue]
    assert holm([p1, *others])[0] < 0.05 <= holm([p_bound, *others])[0]
    a, b = {s: 1e-4 * float(np.exp(v)) for s, v in zip(SHAPES, logs)}, {s: 1e-4 for s in SHAPES}
    assert ratio_p(a, b, 1.5) == pytest.approx(p_bound)
    (row,) = claims.accurate_as_sdf_over_shapes({"shape_suite": out})
    assert row.verdict == claims.NOT_SEPARABLE, row.measured
    assert "against 1.5" in row.measured


def test_a_confirmation_at_the_equivalence_bound_also_needs_its_holm_p():
    """The mirror of the refutation above: an unadjusted interval just below 1.5 whose Holm p against 1.5 (the same
    two-sided test, the same family member) is 0.093 is not separable, not confirmed."""
    import numpy as np

    from ddfbench.report import claims

    logs = np.log(1.5) - np.array([0.05, 0.6, 0.1, 0.3, 0.12, 0.5])
    grid = [0.5, 3.0, 0.6, 2.5, 0.7, 2.0]
    out = []
    for i, shape in enumerate(SHAPES):
        out += [rec("neural_sdf_tuned", shape, 0, 1e-4), rec("ddf_tuned", shape, 0, 1e-4 * float(np.exp(logs[i]))),
                rec("grid_sdf", shape, 0, 1e-4 * grid[i])]
    (row,) = claims.accurate_as_sdf_over_shapes({"shape_suite": out})
    assert "[0.893, 1.44]" in row.measured and "0.093 against 1.5" in row.measured
    assert row.verdict == claims.NOT_SEPARABLE
