"""Report logic on synthetic records: record readers, Pareto front, seed pooling, flags, best marks, noise floor,
plot selection of points, and the files `python -m ddfbench.report` writes."""

import io
import itertools
import json
import math

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from matplotlib.container import BarContainer

from ddfbench.report import plots, records, stats, tables
from ddfbench.report.__main__ import main as report_main
from ddfbench.run.runs import write_json_atomic


def make_record(model="ddf", shape="bunny", seed=0, chamfer=1e-3, status="ok", overrides=(), sampling=None,
                cost=None, probes=(), floor=2e-5, width=64, key=None, scene=None):
    """A record as the runner writes it, with only the fields the report reads."""
    cfg = {"seed": seed, "model": {"family": model, "width": width}, "shape": {"name": shape}, "sampling": sampling or {}}
    return {
        "schema_version": 1, "key": key or f"{model}-{shape}-{width}-{seed}-{json.dumps(sampling, sort_keys=True)}",
        "status": status, "error": None if status == "ok" else "fit of ddf failed: NaN loss",
        "experiment": "synthetic", "family": model if not model.startswith("mesh") else "mesh", "model": model,
        "shape": {"name": shape}, "sampling": sampling or {}, "scene": scene or {},
        "metrics": {} if status != "ok" else {
            "chamfer_l2": chamfer, "chamfer_l1": math.sqrt(chamfer), "fscore": {"0.01": 0.5},
            "sided_gt_to_rec": {"mean": chamfer / 2}, "sided_rec_to_gt": {"mean": chamfer / 2},
            "noise_floor": {"chamfer_l2": floor, "chamfer_l1": 0.004, "fscore": {"0.01": 0.9}}},
        "cost": cost or {}, "counts": {}, "artifacts": {}, "flags": [],
        "fit": {"probes": list(probes)}, "config": cfg,
        "overrides": [f"model={model}", f"shape={shape}", f"seed={seed}", f"model.width={width}", *overrides],
        "env": {"git_sha": "abc"},
    }


# ---------------------------------------------------------------- Pareto front

def brute_force_front(x, y):
    """Points no other point dominates (<= in both, < in one), finite only, as a set of indices."""
    pts = [(i, a, b) for i, (a, b) in enumerate(zip(x, y)) if math.isfinite(a) and math.isfinite(b)]
    keep = set()
    for i, a, b in pts:
        if not any((c <= a and d <= b) and (c < a or d < b) for j, c, d in pts if j != i):
            keep.add(i)
    return keep


coord = st.one_of(st.integers(0, 6).map(float), st.just(math.nan), st.just(math.inf))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(coord, coord), min_size=0, max_size=12))
def test_pareto_front_matches_brute_force(points):
    x = [p[0] for p in points]
    y = [p[1] for p in points]
    front = plots.pareto_front(x, y)
    expected = brute_force_front(x, y)
    # among exact duplicates on the front only one is kept
    assert {(x[i], y[i]) for i in front} == {(x[i], y[i]) for i in expected}
    assert len(front) == len({(x[i], y[i]) for i in front})
    assert list(np.array(x)[front]) == sorted(np.array(x)[front])  # ordered by cost
    ys = np.array(y)[front]
    assert np.all(np.diff(ys) < 0)  # and error falls strictly along it


def test_pareto_front_of_a_known_set():
    x = [1, 2, 3, 4, 2.5]
    y = [5, 3, 3, 1, 4]
    assert plots.pareto_front(x, y).tolist() == [0, 1, 3]


# ---------------------------------------------------------------- tables

def test_seeds_pool_into_mean_std_with_n():
    recs = [make_record(seed=s, chamfer=c) for s, c in zip((0, 1, 2), (1e-3, 2e-3, 6e-3))]
    recs += [make_record(width=128, seed=s, chamfer=5e-4) for s in (0, 1, 2)]
    df = tables.summarize(recs)
    assert len(df) == 2
    row = df[df["model.width"] == "64"].iloc[0]
    assert row["n"] == 3 and row["n_failed"] == 0
    assert row["chamfer_l2_mean"] == pytest.approx(3e-3)
    assert row["chamfer_l2_std"] == pytest.approx(np.std([1e-3, 2e-3, 6e-3], ddof=1))
    assert set(row["keys"].split()) == {r["key"] for r in recs[:3]}


def test_rows_follow_the_sweep_by_model_then_shape_even_within_one_second():
    """Start times have 1 s resolution: runs of one second must still group by model, then shape."""
    order = [("lod10k", "bunny", "08:12:12"), ("lod10k", "airplane", "08:12:13"), ("lod2k", "bunny", "08:12:13"),
             ("lod10k", "cow", "08:12:13"), ("lod2k", "airplane", "08:12:14"), ("lod2k", "cow", "08:12:14")]
    recs = []
    for model, shape, t in order:
        recs.append(make_record(model=model, shape=shape))
        recs[-1]["started"] = f"2026-11-21T{t}+00:00"
    df = tables.summarize(recs)
    assert list(zip(df["model"], df["shape"])) == [
        ("lod10k", "bunny"), ("lod10k", "airplane"), ("lod10k", "cow"),
        ("lod2k", "bunny"), ("lod2k", "airplane"), ("lod2k", "cow")]


def test_failed_and_missing_seeds_are_flagged_not_hidden():
    recs = [make_record(seed=s) for s in (0, 1, 2)]
    recs += [make_record(width=128, seed=0), make_record(width=128, seed=1, status="failed")]
    recs += [make_record(width=256, seed=0)]  # two seeds never ran
    df = tables.summarize(recs)
    by_width = {r["model.width"]: r for _, r in df.iterrows()}
    assert (by_width["128"]["n"], by_width["128"]["n_failed"], by_width["128"]["n_expected"]) == (1, 1, 3)
    assert (by_width["256"]["n"], by_width["256"]["n_failed"]) == (1, 0)
    md = tables.to_markdown(df)
    assert "1/3† (1 failed)" in md and "| 1/3† |" in md and "| 3 |" in md
    assert "NaN loss" in md and "fewer ok runs" in md


def seeded(shape, width, chamfer, spread=0.01):
    """Three seeds of one configuration, chamfer * (1 - spread, 1, 1 + spread)."""
    return [make_record(shape=shape, width=width, seed=s, chamfer=chamfer * (1 + spread * (s - 1))) for s in (0, 1, 2)]


def test_best_is_marked_per_shape_and_per_direction():
    recs = seeded("bunny", 64, 3e-3) + seeded("bunny", 128, 1e-3) + seeded("cow", 64, 2e-3) + seeded("cow", 128, 4e-3)
    df = tables.summarize(recs)
    marked = {(r["shape"], r["model.width"]): m for (_, r), m in zip(df.iterrows(), tables.marks(df, "chamfer_l2")) if m}
    assert marked == {("bunny", "128"): "best", ("cow", "64"): "best"}
    df.loc[:, "fscore@0.01_mean"] = [0.1, 0.9, 0.8, 0.2]
    df.loc[:, "fscore@0.01_ci_lo"] = df["fscore@0.01_mean"] - 0.01
    df.loc[:, "fscore@0.01_ci_hi"] = df["fscore@0.01_mean"] + 0.01
    high = {(r["shape"], r["model.width"]): m for (_, r), m in zip(df.iterrows(), tables.marks(df, "fscore@0.01")) if m}
    assert high == {("bunny", "128"): "best", ("cow", "64"): "best"}
    lines = [line.strip("|").split(" | ") for line in tables.to_markdown(df).splitlines() if line.startswith("| ")]
    col = [c.strip() for c in lines[0]].index("CD-L2 ×10³")
    assert [row[col].strip().split(" ±")[0] for row in lines[1:5]] == ["3", "**1", "**2", "4"]  # x10^3, bold winners


def test_overlapping_intervals_are_ties_not_bold():
    """Means 1.00 and 1.05 (×10⁻³) with a 10 % seed spread: the t intervals overlap, so no bold; both tied,
    the separated third row is not. Shrinking the spread separates them and the best turns bold."""
    recs = seeded("bunny", 64, 1.05e-3, 0.1) + seeded("bunny", 128, 1.0e-3, 0.1) + seeded("bunny", 256, 9e-3, 0.1)
    df = tables.summarize(recs)
    assert list(tables.marks(df, "chamfer_l2")) == ["tie", "tie", ""]
    assert (df["chamfer_l2_ci_lo"] < df["chamfer_l2_mean"]).all() and (df["chamfer_l2_mean"] < df["chamfer_l2_ci_hi"]).all()
    md = tables.to_markdown(df).split("\n\n")[0]
    assert "**" not in md.split("CD-L1")[0] and md.count(tables.TIE) >= 2
    sharp = seeded("bunny", 64, 1.05e-3, 0.001) + seeded("bunny", 128, 1.0e-3, 0.001)
    assert list(tables.marks(tables.summarize(sharp), "chamfer_l2")) == ["", "best"]


def test_ci_is_a_t_interval_over_seeds():
    from scipy import stats as sps

    recs = [make_record(seed=s, chamfer=c) for s, c in zip((0, 1, 2, 3), (1e-3, 2e-3, 4e-3, 3e-3))]
    row = tables.summarize(recs).iloc[0]
    half = sps.t.ppf(0.975, 3) * np.std([1, 2, 4, 3], ddof=1) / 2 * 1e-3
    assert row["chamfer_l2_ci_hi"] - row["chamfer_l2_mean"] == pytest.approx(half)
    assert row["chamfer_l2_mean"] - row["chamfer_l2_ci_lo"] == pytest.approx(half)


def test_welch_ratio_is_the_unequal_variance_t_test_of_two_samples_of_logs():
    """welch_ratio(log x, log y): exp of the difference of mean logs, its Welch–Satterthwaite t interval at the given
    level and scipy's unequal-variance t test p on the logs; two constant samples give the ratio alone."""
    from scipy import stats as sps

    a, b = np.log([1.0e-3, 1.4e-3, 0.9e-3, 1.1e-3, 1.05e-3]), np.log([2.0e-3, 6.5e-3, 1.2e-3])  # unequal spreads
    w = stats.welch_ratio(a, b)
    assert w["p"] == pytest.approx(sps.ttest_ind(a, b, equal_var=False).pvalue, rel=1e-9)
    diff = np.mean(a) - np.mean(b)
    va, vb = np.var(a, ddof=1) / 5, np.var(b, ddof=1) / 3
    df = (va + vb) ** 2 / (va**2 / 4 + vb**2 / 2)  # Welch–Satterthwaite
    assert w["ratio"] == pytest.approx(np.exp(diff), rel=1e-12)
    for level, q in ((0.95, 0.975), (0.9, 0.95)):
        half = sps.t.ppf(q, df) * np.sqrt(va + vb)
        got = w if level == 0.95 else stats.welch_ratio(a, b, level=level)
        assert (got["lo"], got["hi"]) == pytest.approx((np.exp(diff - half), np.exp(diff + half)), rel=1e-9), level
    assert stats.welch_ratio(np.log([2.0, 2.0]), np.log([0.5, 0.5, 0.5])) == pytest.approx({"ratio": 4.0})


def test_no_interval_bound_leaves_the_metric_s_range():
    """Skewed seeds (one chamfer 20x the others, F-scores near 1, a signed offset) give t intervals across 0 and 1;
    the table cuts them to [0, inf), [0, 1], and leaves the signed offset's alone."""
    recs = [make_record(seed=s, chamfer=c) for s, c in zip((0, 1, 2), (1e-3, 1e-3, 2e-2))]
    for r, f, off in zip(recs, (0.999, 0.95, 0.999), (-1e-3, 2e-3, 9e-3)):
        r["metrics"]["fscore"]["0.01"], r["metrics"]["level_offset"] = f, off
    row = tables.summarize(recs).iloc[0]
    raw = stats.summarize_values([1e-3, 1e-3, 2e-2])
    assert raw.lo < 0 and row["chamfer_l2_ci_lo"] == 0.0 and row["chamfer_l2_ci_hi"] == pytest.approx(raw.hi)
    assert stats.summarize_values([0.999, 0.95, 0.999]).hi > 1 and row["fscore@0.01_ci_hi"] == 1.0
    offset = stats.summarize_values([-1e-3, 2e-3, 9e-3])
    assert offset.lo < 0 and row["level_offset_ci_lo"] == pytest.approx(offset.lo)
    assert stats.metric_range("normal_angle_deg") == (0.0, 180.0) and stats.metric_range("mask_iou") == (0.0, 1.0)


def test_a_new_metric_declaration_reaches_the_table_with_its_empty_penalty(monkeypatch):
    from ddfbench.evaluate import metric_registry
    from ddfbench.evaluate.metrics import penalty_metrics

    new = metric_registry.Metric("hausdorff", ("metrics", "hausdorff"), "Hausdorff ×10³", 1e3, penalty=7.5)
    monkeypatch.setattr(metric_registry, "METRICS", [*metric_registry.METRICS, new])
    empty = penalty_metrics([0.01])
    assert empty["hausdorff"] == 7.5 and empty["empty_reconstruction"]
    recs = [make_record(width=64), make_record(width=128), make_record(width=128, seed=1)]
    recs[0]["metrics"]["hausdorff"] = 0.002
    recs[1]["metrics"] = {**empty, "noise_floor": recs[1]["metrics"]["noise_floor"]}
    recs[2]["metrics"]["hausdorff"] = 0.004
    df = tables.summarize(recs)
    assert sorted(df["hausdorff_mean"]) == pytest.approx([0.002, 3.752])  # the empty run counts its penalty
    md = tables.to_markdown(df)
    # the row with an empty run is not ranked, which leaves one ranked row: nothing is marked
    assert "Hausdorff ×10³" in md and "| 3752 ± 5.3e+03 |" in md and "| 2 |" in md


def test_noise_floor_is_its_own_row_per_shape():
    recs = [make_record(shape="bunny", floor=2e-5), make_record(shape="bunny", width=128, floor=4e-5),
            make_record(shape="cow", floor=1e-5)]
    df = tables.summarize(recs)
    floors = tables.noise_floor_rows(df)
    got = dict(zip(floors["shape"], floors["chamfer_l2_mean"]))
    assert got == pytest.approx({"bunny": 3e-5, "cow": 1e-5})
    md_rows = [line for line in tables.to_markdown(df).splitlines() if line.startswith("| noise floor")]
    assert len(md_rows) == 2 and "| 0.03 |" in md_rows[0] + md_rows[1]  # 3e-5 x 10^3


def test_rows_are_labelled_by_the_overrides_that_vary():
    recs = [make_record(overrides=[f"capacity=c{i}", "train.max_seconds=15", "out_dir=/x"], width=w)
            for i, w in ((1, 64), (2, 128))]
    df = tables.summarize(recs)
    assert "capacity" in df.columns and "train.max_seconds" not in df.columns and "out_dir" not in df.columns
    assert sorted(df["capacity"]) == ["c1", "c2"]
    runs = tables.per_run(recs + [make_record(overrides=["capacity=c2"], width=128, seed=1)])
    assert list(runs.columns[:7]) == ["key", "status", "error", "experiment", "model", "family", "shape"]
    assert set(runs.columns[7:9]) == {"capacity", "model.width"}  # the swept values, after the shape
    assert list(runs["capacity"]) == ["c1", "c2", "c2"] and list(runs["seed"]) == [0, 0, 1]
    assert not any(c.startswith("_") for c in runs.columns)


def test_markdown_latex_csv_render_the_same_numbers(tmp_path):
    recs = [make_record(seed=s, chamfer=c) for s, c in ((0, 1e-3), (1, 3e-3))] + [make_record(width=128)]
    df = tables.summarize(recs)
    md, tex = tables.to_markdown(df), tables.to_latex(df)
    tables.to_csv(df, tmp_path / "t.csv")
    csv = pd.read_csv(tmp_path / "t.csv")
    assert len(csv) == 3 and csv["model"].tolist()[-1] == tables.FLOOR_MODEL  # 2 configs + 1 floor row
    assert csv["chamfer_l2_mean"].iloc[0] == pytest.approx(2e-3)  # unscaled in the CSV
    assert "2 ± 1.4" in md  # x10^3 in the rendered tables
    assert r"2 $\pm$ 1.4" in tex
    assert tex.count("{") == tex.count("}") and tex.startswith(r"\begin{tabular}") and r"\end{tabular}" in tex
    body = [line for line in tex.splitlines() if line.endswith(r"\\")]
    assert len({line.count("&") for line in body}) == 1  # every row has as many cells as the header


# ---------------------------------------------------------------- record readers

def test_record_readers_skip_failed_runs_and_read_what_is_missing_as_nan():
    ok, failed = make_record(shape="cow", chamfer=2e-3), make_record(seed=1, status="failed")
    assert records.ok_records([failed, ok]) == [ok]
    assert (records.shape_name(ok), records.shape_name({})) == ("cow", "None")
    assert records.chamfer_l2(ok) == 2e-3 and math.isnan(records.chamfer_l2(failed))
    assert records.chamfer_l2({"metrics": {"chamfer_l2": "inf"}}) == math.inf  # the writer's strict-JSON infinity
    assert [records.as_float(v) for v in (3, "0.5", "inf")] == [3.0, 0.5, math.inf]
    assert all(math.isnan(records.as_float(v)) for v in (None, "n/a", [1.0]))


# ---------------------------------------------------------------- plot data

def surface(fc, dr, p):
    return {"strategy": "surface", "s_fc": fc, "s_dr": dr, "s_p": p}


def test_ablation_lines_take_one_factor_at_a_time():
    grid = list(itertools.product((10, 20, 30), repeat=3))
    recs = [make_record(sampling=surface(*g), chamfer=1e-3 * sum(g)) for g in grid]
    recs.append(make_record(sampling=surface(10, 10, 20), seed=1, chamfer=1e-3 * 50))  # a second seed
    lines = plots.ablation_lines(recs)
    assert [lv for lv, _, _ in lines["s_p"]] == [10, 20, 30]
    assert lines["s_fc"] == [(10, pytest.approx(0.03), 0.0), (20, pytest.approx(0.04), 0.0), (30, pytest.approx(0.05), 0.0)]
    assert lines["s_p"][1][1] == pytest.approx((0.04 + 0.05) / 2)  # seeds averaged
    assert lines["s_p"][1][2] == pytest.approx(np.std([0.04, 0.05], ddof=1))


def test_sampling_lines_follow_labels_per_strategy_and_skip_meshes():
    recs = [make_record(sampling={"strategy": s, "n_samples": n}, chamfer=1 / n)
            for s in ("random", "pov") for n in (4000, 1000, 2000)]
    recs.append(make_record(model="mesh", sampling={"strategy": None, "kind": None}))  # a mesh draws no samples
    recs.append(make_record(sampling={"strategy": "pov", "n_samples": 8000}, status="failed"))
    lines = plots.sampling_lines(recs)
    assert set(lines) == {("ddf", "random"), ("ddf", "pov")}
    assert [n for n, _, _ in lines[("ddf", "pov")]] == [1000, 2000, 4000]


@pytest.fixture
def drawn(monkeypatch):
    """{plot name: figure}: plots._save patched to keep each figure instead of writing it."""
    figures = {}

    def keep(fig, out_dir, name):
        figures[name] = fig
        return [name]

    monkeypatch.setattr(plots, "_save", keep)
    yield figures
    for fig in figures.values():
        plt.close(fig)


def bar_heights(ax):
    """{(tick label under the bar, bar label): (height, half error bar or None)} of the bars drawn on ax."""
    ticks = [t.get_text() for t in ax.get_xticklabels()]
    out = {}
    for bars in ax.containers:
        if not isinstance(bars, BarContainer):
            continue
        errs = bars.errorbar.lines[2][0].get_segments() if bars.errorbar else [None] * len(bars)
        for patch, seg in zip(bars, errs):
            tick = ticks[round(patch.get_x() + patch.get_width() / 2)]
            out[(tick, bars.get_label())] = (patch.get_height(), None if seg is None else (seg[1][1] - seg[0][1]) / 2)
    return out


def test_render_time_bars_are_the_mean_cold_and_warm_render_per_model_and_size(drawn):
    """Each bar is the mean render_cold_s / render_warm_s over the ok runs of one model at one image size; a model
    without runs at a size gets no bar (NaN), failed runs and runs that rendered nothing are left out."""
    runs = {("ddf", 32, 32): [(0.9, 0.1), (1.5, 0.3)], ("ddf", 64, 48): [(2.0, 0.5), (3.0, 0.7), (4.0, 0.6)],
            ("mesh", 32, 32): [(0.05, 0.02)]}
    recs = [make_record(model=m, seed=i, scene={"width": w, "height": h},
                        cost={"render_cold_s": cold, "render_warm_s": warm})
            for (m, w, h), times in runs.items() for i, (cold, warm) in enumerate(times)]
    recs.append(make_record(model="mesh", seed=5, status="failed", scene={"width": 64, "height": 48},
                            cost={"render_cold_s": 9.0, "render_warm_s": 9.0}))
    recs.append(make_record(model="grid_sdf", cost={"fit_s": 1.0}))  # no render
    assert plots.plot_render_time(recs, "/unused") == ["render_time"]
    (ax,) = drawn["render_time"].axes
    heights = {key: h for key, (h, _) in bar_heights(ax).items()}
    assert [t.get_text() for t in ax.get_xticklabels()] == ["ddf", "mesh"]
    expected = {("ddf", "32×32 cold"): 1.2, ("ddf", "32×32 warm"): 0.2, ("ddf", "64×48 cold"): 3.0,
                ("ddf", "64×48 warm"): 0.6, ("mesh", "32×32 cold"): 0.05, ("mesh", "32×32 warm"): 0.02,
                ("mesh", "64×48 cold"): math.nan, ("mesh", "64×48 warm"): math.nan}  # the means of `runs`
    assert heights == pytest.approx(expected, nan_ok=True)


def test_frames_by_shape_bars_are_the_mean_warm_frame_over_seeds_with_its_std(drawn):
    """One bar per shape and model: the mean render_warm_s over the ok seeds, its error bar the std over seeds (0 for
    one seed); shapes ordered by the mesh's face count, which their tick names."""
    warm = {("bunny", "ddf"): [0.2, 0.4, 0.9], ("bunny", "mesh"): [0.01, 0.03], ("sphere", "ddf"): [0.5],
            ("sphere", "mesh"): [0.002, 0.004]}
    faces = {"bunny": 5000, "sphere": 1280}
    recs = []
    for (shape, model), values in warm.items():
        for seed, w in enumerate(values):
            recs.append(make_record(model=model, shape=shape, seed=seed, cost={"render_warm_s": w}))
            recs[-1]["fit"]["faces"] = faces[shape] if model == "mesh" else None
    recs.append(make_record(model="ddf", shape="bunny", seed=7, status="failed", cost={"render_warm_s": 50.0}))
    assert plots.plot_frames_by_shape(recs, "/unused") == ["frames_by_shape"]
    (ax,) = drawn["frames_by_shape"].axes
    assert [t.get_text() for t in ax.get_xticklabels()] == ["sphere\n1,280 faces", "bunny\n5,000 faces"]
    bars = {(tick.split("\n")[0], model): v for (tick, model), v in bar_heights(ax).items()}
    assert set(bars) == set(warm)
    for key, values in warm.items():
        height, half = bars[key]
        assert height == pytest.approx(np.mean(values)), key
        assert half == pytest.approx(np.std(values, ddof=1) if len(values) > 1 else 0.0, abs=1e-12), key


def test_fit_curves_draw_each_runs_positive_probes_per_shape_with_empty_meshes_as_crosses(drawn):
    """One line per ok run with two or more finite positive probes, in its shape's panel: x the probe's fit seconds,
    y its chamfer L2; a probe at the empty-mesh penalty is a cross, the others dots."""
    penalty = plots.PENALTY_CHAMFER_L2  # the value that marks an empty reconstruction (input, not output)
    probes = {
        ("ddf", "bunny"): [(0.5, 4e-3), (2.0, 1e-3), (8.0, 3e-4)],
        ("neural_sdf", "bunny"): [(0.0, 5e-3), (1.0, penalty), (4.0, 2e-3), (16.0, None)],  # t=0, no value: undrawn
        ("ddf", "sphere"): [(0.25, 6e-4), (1.0, 1e-4)],
        ("neural_sdf", "sphere"): [(1.0, 1e-3)],  # one probe: no line
    }

    def as_probes(pts):
        return [{"step": i, "seconds": t, "chamfer_l2": c} for i, (t, c) in enumerate(pts)]

    recs = [make_record(model=m, shape=s, probes=as_probes(p)) for (m, s), p in probes.items()]
    failed = as_probes([(1.0, 1.0), (2.0, 1.0)])
    recs.append(make_record(model="ddf", shape="sphere", seed=3, status="failed", probes=failed))
    assert plots.plot_fit_curves(recs, "/unused") == ["fit_curves"]
    expected = {"bunny": {((0.5, 2.0, 8.0), (4e-3, 1e-3, 3e-4)), ((1.0, 4.0), (penalty, 2e-3))},
                "sphere": {((0.25, 1.0), (6e-4, 1e-4))}}
    axes = drawn["fit_curves"].axes
    assert [ax.get_title() for ax in axes] == ["bunny", "sphere"]
    for ax in axes:
        curves = {(tuple(ln.get_xdata()), tuple(ln.get_ydata())) for ln in ax.get_lines()
                  if ln.get_linestyle() == "-" and ln.get_marker() in ("None", "", None)}
        assert curves == expected[ax.get_title()], ax.get_title()
        marks = {m: sorted(y for ln in ax.get_lines() if ln.get_marker() == m for y in ln.get_ydata()) for m in "ox"}
        drawn_y = sorted(y for _, ys in expected[ax.get_title()] for y in ys)
        assert marks["x"] == [y for y in drawn_y if y == penalty]
        assert marks["o"] == [y for y in drawn_y if y != penalty]


def test_report_command_writes_parseable_files(tmp_path):
    probes = [{"step": s, "seconds": 0.1 * s, "chamfer_l2": 1e-2 / s} for s in (1, 2, 4, 8)]
    recs = []
    for i, (model, fc) in enumerate((("ddf", 10), ("ddf", 20), ("mesh_lod500", 10))):
        recs.append(make_record(model=model, width=64 + i, sampling=surface(fc, 10, 10) | {"n_samples": 1000 * fc},
                                probes=probes, scene={"width": 32, "height": 32},
                                cost={"fit_s": 1.0 + i, "storage_bytes": 1e4 * (i + 1), "render_warm_s": 0.1,
                                      "render_cold_s": 0.3}))
    for r in recs:
        write_json_atomic(str(tmp_path / "rec" / r["key"] / "record.json"), r)
    out = tmp_path / "rep"
    assert report_main([str(tmp_path / "rec"), "--out", str(out), "--note", "reduced budget: x=1",
                        "--plots", ",".join(plots.PLOTS)]) == 0
    report = (out / "report.md").read_text()
    assert report.splitlines()[2] == "**reduced budget: x=1**"
    assert all(r["key"] in report for r in recs)
    for kind in plots.PLOTS:
        assert (out / f"{kind}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        pdf = (out / f"{kind}.pdf").read_bytes()
        assert pdf.startswith(b"%PDF") and b"%%EOF" in pdf[-32:]
    assert len(pd.read_csv(io.StringIO((out / "table.csv").read_text()))) == 4
    assert report_main([str(tmp_path / "rec"), "--plots", "nope"]) == 2
    assert report_main([str(tmp_path / "missing")]) == 2


def test_report_keeps_each_runs_values_in_runs_csv(tmp_path):
    recs = [make_record(seed=s, chamfer=c) for s, c in ((0, 1e-3), (1, 4e-3), (2, 2.5e-3))]
    recs.append(make_record(seed=3, status="failed"))
    for r in recs:
        write_json_atomic(str(tmp_path / "rec" / r["key"] / "record.json"), r)
    assert report_main([str(tmp_path / "rec"), "--out", str(tmp_path / "rep"), "--plots", "none"]) == 0
    runs = pd.read_csv(tmp_path / "rep" / "runs.csv")
    assert sorted(runs["key"]) == sorted(r["key"] for r in recs)
    ok = runs[runs["status"] == "ok"].set_index("seed")["chamfer_l2"]
    assert ok.to_dict() == pytest.approx({0: 1e-3, 1: 4e-3, 2: 2.5e-3})
    assert runs.loc[runs["seed"] == 3, "status"].item() == "failed"
    table = pd.read_csv(tmp_path / "rep" / "table.csv")
    assert table.loc[table["model"] == "ddf", "chamfer_l2_mean"].item() == pytest.approx(2.5e-3)


def test_every_experiment_has_a_plot_selection():
    import os

    conf = os.path.join(os.path.dirname(__file__), "..", "conf", "experiment")
    names = {f[:-5] for f in os.listdir(conf) if f.endswith(".yaml")} - {"default", "ablation_grid"}
    assert names <= set(plots.PLOTS_BY_EXPERIMENT)
    assert all(set(k) <= set(plots.PLOTS) for k in plots.PLOTS_BY_EXPERIMENT.values())


def test_equal_values_are_not_marked_and_empty_reconstructions_are_counted():
    recs = [make_record(width=w, chamfer=8.64) for w in (64, 128)]
    recs[1]["metrics"]["empty_reconstruction"] = True
    df = tables.summarize(recs)
    assert (tables.marks(df, "chamfer_l2") == "").all()  # neither best nor tied
    assert sorted(df["n_empty"]) == [0, 1]
    md = tables.to_markdown(df)
    assert "**" not in md.split("\n\n")[0] and "1 (1 empty)" in md and "defined penalty" in md


def test_a_fit_that_never_found_the_shape_is_counted_and_a_row_of_them_is_not_converged():
    def run(model, seed, widest_f):
        rec = make_record(model=model, seed=seed, chamfer=0.2 if widest_f == 0 else 2e-3)
        rec["metrics"]["fscore"] = {"0.01": widest_f / 2, "0.02": widest_f}
        return rec

    # a closed blob away from the shape: a mesh, measured, but F@0.02 = 0
    mixed = [run("gan_sdf", 0, 0.57), run("gan_sdf", 1, 0.58), run("gan_sdf", 2, 0.0)]
    lost = [run("gan_lost", s, 0.0) for s in (0, 1, 2)]
    near = [run("gan_near", s, f) for s, f in ((0, 1e-3), (1, 0.6), (2, 0.5))]  # a few points near: not off the shape
    unjudged = make_record(model="mesh_lod500")  # no F@0.02 in the record: not judged
    both = [run("gan_both", s, 0.0) for s in (0, 1, 2)]
    both[0]["metrics"]["empty_reconstruction"] = True  # one empty and two off the shape: no result either
    df = tables.summarize(mixed + lost + near + both + [unjudged]).set_index("model")
    assert df.loc["gan_both", "not_converged"] and (df.loc["gan_both", "n_empty"], df.loc["gan_both", "n_off"]) == (1, 2)
    assert (df.loc["gan_sdf", "n_off"], df.loc["gan_lost", "n_off"], df.loc["gan_near", "n_off"]) == (1, 3, 0)
    assert df.loc["mesh_lod500", "n_off"] == 0
    assert df.loc["gan_lost", "not_converged"] and not df.loc["gan_sdf", "not_converged"]
    assert df.loc["gan_sdf", "chamfer_l2_mean"] == pytest.approx((2e-3 + 2e-3 + 0.2) / 3)  # measured: kept in the mean
    summary = tables.summarize(mixed + lost + near + both + [unjudged])
    assert tables.marks(summary, "chamfer_l2")[summary["model"].isin(["gan_lost", "gan_both"])].eq("").all()
    md = tables.to_markdown(summary)
    assert "3 (1 empty) (2 off the shape) not converged | – |" in md
    assert "3 (1 off the shape)" in next(line for line in md.splitlines() if line.startswith("| gan_sdf"))
    assert "3 (3 off the shape) not converged" in next(line for line in md.splitlines() if line.startswith("| gan_lost"))
    assert "(k off the shape): k runs gave a surface with F@0.02 = 0" in md
    assert md.splitlines()[0].startswith("| model | shape | budget | n | CD-L2")  # a count, not a label column
    # the Pareto plot draws a row with a run of no result as a cross, off the front, as the table leaves it unranked
    points = {p["model"]: p["empty"] for p in plots._config_points(mixed + lost + near + both, "fit_s")}
    assert points == {"gan_sdf": True, "gan_lost": True, "gan_near": False, "gan_both": True}
    assert set(tables.ranked(df.reset_index())["model"]) == {"gan_near", "mesh_lod500"}


def test_intervals_that_touch_overlap_and_an_interval_without_bounds_overlaps_all():
    """overlaps: closed intervals, so a shared end point is an overlap (a tie, not a bold best); a NaN bound (n < 2)
    cannot separate. Kills strict < in overlaps, which only the committed-report regeneration caught."""
    assert stats.overlaps((0.0, 1.0), (1.0, 2.0)) and stats.overlaps((1.0, 2.0), (0.0, 1.0))
    assert not stats.overlaps((0.0, 1.0), (1.0 + 1e-9, 2.0))
    assert stats.overlaps((0.0, 1.0), (math.nan, math.nan)) and stats.overlaps((0.0, 1.0), (5.0, math.nan))
    assert stats.best_and_ties([0.5, 1.5, 3.0], [(0.0, 1.0), (1.0, 2.0), (2.5, 3.5)], "low") == {0: "tie", 1: "tie"}
    assert stats.best_and_ties([0.5, 1.5], [(0.0, 0.9), (1.0, 2.0)], "low") == {0: "best"}
    assert stats.best_and_ties([0.5, 1.5], [(0.0, 0.9), (1.0, 2.0)], "high") == {1: "best"}


def test_a_row_with_an_empty_run_is_not_ranked_nor_tied_with_the_best():
    """1 empty run of 3 puts the penalty (8.64) in the row's mean and widens its interval past every other: ranked,
    it would tie with the best and take its bold away."""
    best = seeded("bunny", 64, 1.0e-3, 0.01)
    second = seeded("bunny", 128, 2.0e-3, 0.01)
    holed = [make_record(width=256, seed=s, chamfer=c) for s, c in ((0, 1.0e-3), (1, 1.0e-3), (2, 8.64))]
    holed[2]["metrics"]["empty_reconstruction"] = True
    df = tables.summarize(best + second + holed)
    assert df.loc[2, "chamfer_l2_ci_lo"] <= df.loc[0, "chamfer_l2_ci_hi"]  # its interval does overlap the best's
    assert list(tables.marks(df, "chamfer_l2")) == ["best", "", ""]
    md = tables.to_markdown(df)
    assert "**1 ±" in md and "the row is not ranked" in md


def test_the_table_names_its_evaluation_point_count():
    recs = seeded("bunny", 64, 1e-3) + seeded("bunny", 128, 2e-3)
    for r in recs:
        r["config"]["eval"] = {"n_points": 100000 if r["config"]["model"]["width"] == 64 else 20000}
    df = tables.summarize(recs)
    assert sorted(df["eval_points"]) == [20000, 100000]
    md = tables.to_markdown(df)
    assert "on 20,000 or 100,000 points a surface (by row: table.csv's eval_points)" in md
    assert "eval_points" not in md.splitlines()[0]  # not a label column
    assert "on 100,000 points a surface." in tables.to_markdown(tables.summarize(recs[:3]))
    assert "the evaluation point count is not recorded" in tables.to_markdown(tables.summarize(seeded("bunny", 64, 1e-3)))
    again = seeded("bunny", 64, 1e-3)  # measured again (ddfbench.report.reevaluate): the metrics' own count wins
    for r in again:
        r["config"]["eval"], r["metrics"]["n_points"] = {"n_points": 20000}, 100000
    assert "on 100,000 points a surface." in tables.to_markdown(tables.summarize(again))


def test_a_value_defined_in_fewer_runs_than_n_says_over_how_many():
    recs = [make_record(seed=s, chamfer=1e-3 * (1 + s)) for s in range(3)]
    for r, mae in zip(recs, (2e-3, 4e-3, None)):  # the third render hit no pixel the reference hit
        r["metrics"]["depth_mae"] = mae
    df = tables.summarize(recs)
    assert df.loc[0, "n"] == 3 and df.loc[0, "depth_mae_n"] == 2 and df.loc[0, "chamfer_l2_n"] == 3
    assert df.loc[0, "depth_mae_mean"] == pytest.approx(3e-3)
    md = tables.to_markdown(df)
    row = md.splitlines()[2]
    assert row.count("(of 2)") == 1 and "3 ± 1.4 (of 2)" in row and "defined in k of the row's n runs" in md
    assert "depth_mae_n" not in md and "(of " not in tables.to_markdown(tables.summarize(recs[:2]))


def test_records_from_mixed_commits_are_refused_unless_allowed(tmp_path, capsys):
    recs = [make_record(seed=0), make_record(seed=1), make_record(seed=2)]
    recs[1]["env"] = {"git_sha": "def"}
    for r in recs:
        write_json_atomic(str(tmp_path / "rec" / r["key"] / "record.json"), r)
    out = tmp_path / "rep"
    assert report_main([str(tmp_path / "rec"), "--out", str(out), "--plots", "none"]) == 2
    assert (f"records from 2 code commits (def: 1 record, e.g. {tmp_path / 'rec' / recs[1]['key']}; abc: 2 records, "
            "e.g. ") in capsys.readouterr().err  # which records to rerun
    assert not (out / "table.md").exists()
    assert report_main([str(tmp_path / "rec"), "--out", str(out), "--plots", "none", "--allow-mixed-commits"]) == 0
    assert "Mixed code commits: abc, def" in (out / "report.md").read_text()


def test_paired_differences_of_the_ablation_against_its_base():
    from ddfbench.report import paired

    base = {"strategy": "surface", "s_fc": 10, "s_dr": 10, "s_p": 10}
    recs = [make_record(seed=s, sampling=base, chamfer=1e-3 + 1e-5 * s) for s in (0, 1, 2)]
    recs += [make_record(seed=s, sampling=base | {"s_p": 30}, chamfer=5e-4 + 1e-5 * s + 1e-6 * s * s) for s in (0, 1, 2)]
    recs += [make_record(seed=5, sampling=base | {"s_p": 30}, chamfer=1.0)]  # no partner seed: not paired
    for r in recs:
        r["experiment"] = "ablation"
    (row,) = paired.compare_settings(recs, "chamfer_l2", paired.surface_levels, "s_fc=10 s_dr=10 s_p=10")
    assert row["setting"] == "s_fc=10 s_dr=10 s_p=30" and row["diff"].n == 3
    assert row["diff"].mean == pytest.approx(-5e-4 + 5e-6 / 3) and row["diff"].hi < 0
    md = paired.paired_report("ablation", recs)
    assert "| s_fc=10 s_dr=10 s_p=30 | 3 |" in md and "| yes |" in md
    assert paired.paired_report("storage", recs) is None


def test_paired_settings_are_separated_by_their_holm_adjusted_p():
    """Six settings, each with a ratio of about 0.9 on three seeds (raw p near 0.01-0.02): every raw interval excludes
    1, but Holm across the six leaves none separated; one far lower ratio stays separated."""
    from ddfbench.report import paired

    base = {"strategy": "surface", "s_fc": 10, "s_dr": 10, "s_p": 10}
    noise = (1.0, 1.02, 0.98)
    recs = [make_record(seed=s, sampling=base, chamfer=1e-3 * noise[s]) for s in (0, 1, 2)]
    levels = [base | {k: v} for k in ("s_fc", "s_dr", "s_p") for v in (20, 30)]
    for i, lv in enumerate(levels):
        ratio = 0.05 if i == 0 else 0.9
        recs += [make_record(seed=s, sampling=lv, chamfer=1e-3 * noise[s] * ratio * (1, 1.03, 0.995)[s]) for s in (0, 1, 2)]
    rows = paired.compare_settings(recs, "chamfer_l2", paired.surface_levels, "s_fc=10 s_dr=10 s_p=10")
    raw = [stats.t_test_p(r["ratio"]) for r in rows]
    assert all(p < 0.05 for p in raw) and all(np.exp(r["ratio"].hi) < 1 for r in rows)
    md = paired.to_markdown(rows, "chamfer_l2", "s_fc=10 s_dr=10 s_p=10", "same shape and seed")
    seps = [line.rstrip(" |").rsplit("| ", 1)[1] for line in md.splitlines() if line.startswith("| s_")]
    assert seps == ["yes"] + ["no"] * 5 and "Holm-adjusted across the table's 6 settings" in md


def test_sampling_strategies_pair_at_matched_label_counts_and_the_ratio_column_is_the_geometric_mean():
    """The sampling design pairs records on (shape, seed, labels): a strategy at half the baseline's chamfer at every
    label count has ratio 0.5 over all six pairs. Pairing on (shape, seed) alone would pair runs of different label
    counts (and count 3 pairs); a table printing the mean log ratio instead of its exp would print -0.693, not 0.5."""
    from ddfbench.report import paired

    noise = (1.0, 1.1, 0.9)
    recs = []
    for strat, labels, scale in (("random", (1000, 4000), 1.0), ("surface", (4000, 1000), 0.5)):
        for n in labels:
            for s in (0, 1, 2):
                chamfer = (4e-3 if n == 1000 else 1e-3) * noise[s] * scale * (1 + 0.01 * s * (strat == "surface"))
                recs.append(make_record(seed=s, sampling={"strategy": strat, "n_samples": n}, chamfer=chamfer))
    (row,) = paired.compare_settings(recs, "chamfer_l2", paired.strategy, "random", paired.strategy_pair_key)
    assert row["setting"] == "surface" and row["ratio"].n == 6 and row["diff"].n == 6
    assert math.exp(row["ratio"].mean) == pytest.approx(0.5 * (1.01 * 1.02) ** (1 / 3))
    md = paired.paired_report("sampling", recs, metrics=("chamfer_l2",))
    (line,) = [x for x in md.splitlines() if x.startswith("| surface |")]
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[1] == "6" and cells[4] == "0.505"  # geometric mean of 0.5, 0.505, 0.51 (twice each)
    lo, hi = (float(x) for x in cells[5].strip("[]").split(","))
    assert 0.49 < lo < 0.505 < hi < 0.52


def test_a_zero_value_leaves_its_pair_out_of_the_ratio_not_the_difference():
    from ddfbench.report import paired

    a, b = {("s", 0): 1.0, ("s", 1): 2.0, ("s", 2): 3.0}, {("s", 0): 0.0, ("s", 1): 1.0, ("s", 2): 1.5}
    assert paired.difference(a, b).n == 3 and paired.log_ratio(a, b).n == 2
    assert paired.log_ratio(a, b).mean == pytest.approx(math.log(2.0))
    assert paired.log_ratio(b, a).n == 2


def test_a_report_commit_between_runs_is_not_a_code_change(tmp_path):
    recs = [make_record(seed=0), make_record(seed=1)]
    recs[0]["env"] = {"git_sha": "abc", "code_sha": "c0de"}
    recs[1]["env"] = {"git_sha": "def", "code_sha": "c0de"}  # HEAD moved by a reports-only commit
    for r in recs:
        write_json_atomic(str(tmp_path / "rec" / r["key"] / "record.json"), r)
    assert report_main([str(tmp_path / "rec"), "--out", str(tmp_path / "rep"), "--plots", "none"]) == 0


def test_report_says_which_models_built_from_the_exact_mesh(tmp_path):
    recs = [make_record(model=m, key=m) for m in ("ddf", "neural_sdf", "grid_sdf", "mesh_lod500")]
    recs.append({**make_record(model="hashgrid", key="hashgrid"), "family": "hashgrid"})  # not in this checkout
    for r in recs:
        write_json_atomic(str(tmp_path / "rec" / r["key"] / "record.json"), r)
    assert report_main([str(tmp_path / "rec"), "--out", str(tmp_path / "rep"), "--plots", "none"]) == 0
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "- grid_sdf, mesh_lod500: the exact mesh (no training samples)" in text
    assert "- ddf: ray samples" in text and "- neural_sdf: SDF samples" in text
    assert "hashgrid:" not in text


def test_a_row_whose_every_mesh_is_empty_says_not_converged_and_is_not_ranked():
    recs = [make_record(model="ddf_paper", seed=s, chamfer=8.64) for s in (0, 1)]
    for r in recs:
        r["metrics"]["empty_reconstruction"] = True
    recs += [make_record(model="ddf", seed=s, chamfer=c) for s, c in ((0, 2e-3), (1, 2.1e-3))]
    partly = [make_record(model="neural_sdf", seed=s, chamfer=c) for s, c in ((0, 1e-3), (1, 8.64))]
    partly[1]["metrics"]["empty_reconstruction"] = True  # one empty of two: still a result, still ranked
    df = tables.summarize(recs + partly)
    row = df.set_index("model")
    assert row.loc["ddf_paper", "not_converged"] and not row.loc["neural_sdf", "not_converged"]
    assert tables.marks(df, "chamfer_l2")[df["model"] == "ddf_paper"].eq("").all()
    md = tables.to_markdown(df)
    paper = next(line for line in md.splitlines() if line.startswith("| ddf_paper"))
    assert "2 (2 empty) not converged" in paper and "8640" not in paper
    ddf = next(line for line in md.splitlines() if line.startswith("| ddf |"))
    assert "not converged" not in ddf
    assert "not converged: every run's reconstruction was empty" in md


def test_a_report_names_the_scenes_its_image_columns_come_from():
    from ddfbench.report.__main__ import scene_lines

    def rendered(width, n):
        rec = make_record()
        rec["config"]["scene"] = {"name": "normals", "outputs": ["depth", "mask", "normal"], "width": width,
                                  "height": width, "cameras": {"n": n}, "timing": {"repeats": 3, "warmup": 1}}
        return rec

    unrendered = make_record()
    unrendered["config"]["scene"] = {"name": "none", "outputs": []}
    lines = scene_lines([rendered(64, 2), rendered(64, 2), rendered(128, 1), unrendered])
    assert lines[1] == "The image columns come from the scenes:"
    assert "- `normals`: depth, mask, normal at 128×128, 1 camera, against the oracle's render of the exact mesh; warm " \
           "time the median of up to 3 renders after 1 warm-up (1 run)" in lines
    assert any(line.startswith("- `normals`: depth, mask, normal at 64×64, 2 cameras") and line.endswith("(2 runs)")
               for line in lines)
    assert scene_lines([unrendered]) == []
    placed = rendered(64, 2)
    placed["config"]["scene"]["cameras"]["positions"] = [[0, 0, 2], [2, 0, 0], [0, 2, 0]]  # the orbit's n is unused
    assert "at 64×64, 3 cameras," in scene_lines([placed])[3]


def test_files_of_one_name_get_distinct_shape_names_and_their_own_noise_floor_rows():
    """ShapeNet keeps every mesh as models/model_normalized.obj: named by the file name alone, two geometries shared
    a noise-floor row (their mean) and the best marks of one shape."""
    def on_file(path, chamfer, floor):
        rec = make_record(model="mesh", shape="model_normalized", chamfer=chamfer)
        rec["config"]["shape"] = {"name": "file", "path": path}
        rec["metrics"]["noise_floor"] = {"chamfer_l2": floor}
        return rec

    a = on_file("/d/02691156/aa/models/model_normalized.obj", 1e-3, 1e-4)
    b = on_file("/d/02691156/bb/models/model_normalized.obj", 2e-3, 3e-4)
    torus = make_record(model="mesh", shape="torus")
    near = make_record(model="mesh", shape="torus")
    near["config"]["shape"] = {"name": "file", "path": "torus.obj"}  # a bare file name beside the catalog torus
    named = records.distinct_shape_names([a, b, torus, near])
    assert [records.shape_name(r) for r in named] == ["aa/models/model_normalized", "bb/models/model_normalized",
                                                      "torus", "torus (file)"]
    assert named[2] is torus and records.shape_name(a) == "model_normalized"  # the records themselves unchanged
    floors = tables.noise_floor_rows(tables.summarize(named)).set_index("shape")["chamfer_l2_mean"]
    assert floors["aa/models/model_normalized"] == pytest.approx(1e-4)
    assert floors["bb/models/model_normalized"] == pytest.approx(3e-4)
