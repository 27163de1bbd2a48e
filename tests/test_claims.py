"""reports/claims.md from a small set of synthetic records: every listed claim has a row, and a
verdict follows the numbers (flip the numbers, the verdict flips)."""

import re

import numpy as np
import pytest
import scipy.stats

from ddfbench.report import claims
from ddfbench.report.__main__ import main as report_main
from ddfbench.run.runs import write_json_atomic

SEEDS = (0, 1, 2)


def rec(experiment, model, seed, chamfer, shape="bunny", sampling=None, cost=None, scene=None, family=None,
        device="cpu", sha="abc"):
    """A record with only what the claims read."""
    sampling = sampling or {}
    return {"key": f"{experiment}-{model}-{shape}-{seed}-{sorted(sampling.items())}-{sorted((scene or {}).items())}",
            "status": "ok", "schema_version": 1, "experiment": experiment, "model": model, "family": family or model,
            "shape": {"name": shape}, "sampling": sampling, "scene": scene or {},
            "metrics": {"chamfer_l2": chamfer, "n_points": 2000}, "cost": cost or {}, "config": {"seed": seed},
            "env": {"git_sha": sha, "device": device}}


def jitter(seed, x, spread=0.02):
    return x * (1 + spread * (seed - 1))


def ablation(cd30):
    """cd30: {factor: chamfer at level 30}; the base 10/10/10 at 1e-3."""
    out = [rec("ablation", "ddf", s, jitter(s, 1e-3), shape="bone", sampling={"s_fc": 10, "s_dr": 10, "s_p": 10})
           for s in SEEDS]
    for f, cd in cd30.items():
        levels = {k: 30 if k == f else 10 for k in ("s_fc", "s_dr", "s_p")}
        out += [rec("ablation", "ddf", s, jitter(s, cd), shape="bone", sampling=levels) for s in SEEDS]
    return out


def sampling(cd):
    """cd: {strategy: chamfer at 1000 labels} (x 0.1 at 10000)."""
    return [rec("sampling", "ddf", s, jitter(s, c * scale), shape="bone", sampling={"strategy": st, "n_samples": n})
            for st, c in cd.items() for n, scale in ((1000, 1.0), (10000, 0.1)) for s in SEEDS]


def representations(ddf_ratio, sdf=1e-4):
    """The DDF at ddf_ratio x the neural SDF's chamfer on every shape."""
    out = []
    for shape, spread in (("bunny", 0.99), ("cow", 1.01)):  # the ratio differs by shape: a non-zero interval
        out += [rec("representations", claims.DDF, s, jitter(s, ddf_ratio * sdf * spread), shape=shape, family="ddf",
                    cost={"fit_s": 40.0, "n_params": 6e4}) for s in SEEDS]
        out += [rec("representations", claims.SDF, s, jitter(s, sdf), shape=shape, family="neural_sdf",
                    cost={"fit_s": 40.0, "n_params": 9e4}) for s in SEEDS]
    return out


def render_time(device, normal_ratio=4.0, bvh_growth=3.0, reference_load=1.0):
    """Warm frames (the DDF's first frame 2x its warm one), normal errors (the DDF's normal_ratio x the SDF's 6°),
    and the full mesh bvh_growth x slower than its 2,000-face LOD; each run's reference (the full mesh in its own
    process) takes reference_load x the mesh model's frame time."""
    out = []
    for model, family, t, angle in ((claims.DDF, "ddf", 0.08, 6.0 * normal_ratio), (claims.SDF, "neural_sdf", 0.6, 6.0),
                                    ("mesh", "mesh", 0.006, 0.0), ("mesh_lod2000", "mesh", 0.006 / bvh_growth, 8.0)):
        for s in SEEDS:
            r = rec("render_time", model, s, 1e-5, scene={"width": 64}, family=family, device=device,
                    cost={"render_warm_s": jitter(s, t), "render_cold_s": 2 * jitter(s, t),
                          "reference_render_warm_s": reference_load * jitter(s, 0.006)})
            r["metrics"]["normal_angle_deg"] = jitter(s, angle, 0.05)
            r["fit"], r["shape"]["n_faces"] = {"faces": 56172 if model == "mesh" else 2000}, 56172
            out.append(r)
    return out


def storage(g_bytes):
    return [rec("storage", "gan_sdf", 0, 1e-2, cost={"storage_bytes": g_bytes}),
            rec("storage", "mesh", 0, 1e-5, cost={"storage_bytes": 1.07e6}),
            rec("storage", "grid_sdf", 0, 1e-5, cost={"storage_bytes": 8.4e6})]


def records(**over):
    base = {"ablation": ablation({"s_fc": 0.9e-3, "s_dr": 0.95e-3, "s_p": 0.2e-3}),
            "sampling": sampling({"surface": 1e-4, "pov": 3e-4, "random": 9e-4}),
            "representations": representations(3.0),
            "render_time": render_time("cpu"), "storage": storage(50e3)}
    return base | over


def verdicts(recs):
    return {c.claim: c.verdict for c in claims.evaluate(recs)}


def test_every_claim_has_a_row_with_a_verdict():
    v = verdicts(records())
    assert v["s_p matters more than s_fc"] == v["s_p matters more than s_dr"] == claims.CONFIRMED
    assert v["s_fc matters more than s_dr (paper's text)"] == claims.CONFIRMED
    assert v["surface beats pov at equal counts"] == v["pov beats random at equal counts"] == claims.CONFIRMED
    # chamfers compare with the paper's only up to an unknown scale: the rows give the value, not a verdict
    assert v[f"{claims.DDF}: bunny chamfer at most the paper's 0.589×10³"] == claims.NOT_TESTABLE
    # the paper's 10->30 effects (s_p x0.006, s_fc x0.97, s_dr x0.60) against the records' (x0.2, x0.9, x0.95)
    assert v["the paper's effect of s_p 10→30 (CD ×0.00601)"] == claims.REFUTED
    assert v["the paper's effect of s_fc 10→30 (CD ×0.972)"] == claims.REFUTED
    assert v["ddf_paper: bunny chamfer at most the paper's 0.589×10³"] == claims.NO_RECORDS  # no paper_ddf records
    assert v["DDF as accurate as the neural SDF"] == claims.REFUTED  # 3x worse
    assert v[f"DDF renders faster than {claims.SDF}"] == v["DDF renders faster than mesh"] == claims.NOT_TESTABLE
    assert v["the generator G stores in ~47 KB"] == v["G < mesh < grid SDF in storage"] == claims.CONFIRMED
    assert v["GAN more accurate than CNN on 2D SDFs"] == claims.NOT_TESTABLE
    assert set(verdicts({}).values()) == {claims.NO_RECORDS, claims.NOT_TESTABLE}


def test_the_bvh_row_names_the_triangle_counts_and_compares_the_full_mesh_with_its_smallest_lod():
    times = render_time("cpu", bvh_growth=3.0)
    lod500 = [{**r, "model": "mesh_lod500", "fit": {"faces": 500},
               "cost": {**r["cost"], "render_warm_s": r["cost"]["render_warm_s"] / 2}}
              for r in times if r["model"] == "mesh_lod2000"]
    (row,) = [c for c in claims.evaluate(records(render_time=times + lod500))
              if c.claim == "a BVH's frame time grows with the triangle count"]
    assert "mesh / mesh_lod500 6×" in row.measured and "bunny 56,172/500" in row.measured
    assert row.verdict == claims.CONFIRMED


FACES = {"bunny": 56172, "cup": 1020, "chain": 12288, "box": 12}


def render_shapes(ddf_over_sdf, bvh=(3.0, 1.0, 2.0, 1.0), device="cpu"):
    """render_time's families on the FACES shapes: on shape i the DDF's warm frame ddf_over_sdf[i] x the SDF's, its
    cold frame (2 + i/2) x its warm one, the full mesh bvh[i] x slower than its LOD, which keeps min(2,000, faces)."""
    out = []
    for i, (shape, ratio, growth) in enumerate(zip(FACES, ddf_over_sdf, bvh)):
        for r in render_time(device, bvh_growth=growth):
            r = {**r, "experiment": "render_shapes", "shape": {"name": shape}, "scene": {"width": 128},
                 "key": r["key"] + shape, "cost": dict(r["cost"]), "config": {**r["config"], "model": {}}}
            if r["model"] == claims.DDF:
                r["cost"]["render_warm_s"] *= ratio * 0.6 / 0.08
                r["cost"]["render_cold_s"] = (2 + i / 2) * r["cost"]["render_warm_s"]
            if r["model"] == "mesh":
                r["fit"] = {"faces": FACES[shape]}
            if r["model"] == "mesh_lod2000":
                r["fit"], r["config"]["model"] = {"faces": min(2000, FACES[shape])}, {"faces": 2000}
            out.append(r)
    return out


def t_interval(values):
    """exp of the mean log and of its 95 % t interval: the claims' ratio over shapes, computed here by hand."""
    logs = np.log(values)
    half = scipy.stats.t.ppf(0.975, len(logs) - 1) * logs.std(ddof=1) / np.sqrt(len(logs))
    return np.exp(logs.mean()), np.exp(logs.mean() - half), np.exp(logs.mean() + half)


def numbers(text, after):
    """The ratio and its interval bounds written after `after`: '1.23× [0.9, 1.5]'."""
    m = re.search(re.escape(after) + r" ([\d.e+-]+)× \[([\d.e+-]+), ([\d.e+-]+)\]", text)
    return tuple(float(x) for x in m.groups())


def test_render_ratios_over_shapes_take_the_interval_over_shapes_not_seeds():
    rows = {c.claim: c for c in claims.evaluate(records(render_shapes=render_shapes((0.2, 0.3, 0.25, 0.4))))}
    faster = rows[f"DDF renders faster than {claims.SDF}"]
    assert "(n=4 shapes)" in faster.measured and "`render_shapes`: 4 evaluation shapes" in faster.rows
    assert numbers(faster.measured, f"{claims.SDF}") == pytest.approx(t_interval([0.2, 0.3, 0.25, 0.4]), rel=6e-3)
    cold = rows["DDF's first frame slower than its warm frames"]
    assert numbers(cold.measured, claims.DDF) == pytest.approx(t_interval([2, 2.5, 3, 3.5]), rel=6e-3)
    bvh = rows["a BVH's frame time grows with the triangle count"]
    # the box (12 faces) and the cup (1,020) have fewer than 5 x the LOD's triangles: left out, and named nowhere
    assert "(n=2 shapes)" in bvh.measured and "bunny 56,172/2,000, chain 12,288/2,000" in bvh.measured
    assert numbers(bvh.measured, "mesh_lod2000") == pytest.approx(t_interval([3.0, 2.0]), rel=6e-3)
    assert "2 evaluation shapes" in bvh.rows


def test_the_ddf_against_the_mesh_divides_by_the_mesh_timed_in_the_ddf_s_own_process():
    """The mesh model's runs were other processes; under another load they would move the ratio."""
    shapes = render_shapes((0.2, 0.3, 0.25, 0.4))
    for r in shapes:
        if r["model"] == claims.DDF:
            r["cost"]["reference_render_warm_s"] *= 0.8  # the DDF's processes ran under a lighter load
    row = {c.claim: c for c in claims.evaluate(records(render_shapes=shapes))}["DDF renders faster than mesh"]
    # per run: (0.08 x ratio x 0.6 / 0.08) / (0.8 x 0.006) = ratio x 125, the same for every seed of a shape
    assert numbers(row.measured, "mesh") == pytest.approx(t_interval([25.0, 37.5, 31.25, 50.0]), rel=6e-3)
    assert "in its process" in row.measured


def test_render_claims_prefer_records_over_shapes_that_hold_the_claim_s_models_and_a_gpu_for_a_gpu_claim():
    slow = records(render_time=render_time("cuda"), render_shapes=render_shapes((2.0, 3.0, 2.5, 4.0), device="cuda"))
    assert verdicts(slow)[f"DDF renders faster than {claims.SDF}"] == claims.REFUTED  # the bunny alone: confirmed
    assert verdicts(records(render_time=render_time("cuda")))[f"DDF renders faster than {claims.SDF}"] == claims.CONFIRMED
    # over shapes but on the CPU: the GPU claim reads the bunny's CUDA records
    cpu_shapes = records(render_time=render_time("cuda"), render_shapes=render_shapes((2.0, 3.0, 2.5, 4.0)))
    assert verdicts(cpu_shapes)[f"DDF renders faster than {claims.SDF}"] == claims.CONFIRMED
    # a sweep over shapes without the DDF: its claims fall back to the bunny's records
    no_ddf = [r for r in render_shapes((2.0, 3.0, 2.5, 4.0)) if r["model"] != claims.DDF]
    rows = {c.claim: c for c in claims.evaluate(records(render_shapes=no_ddf))}
    assert rows[f"DDF renders faster than {claims.SDF}"].rows.startswith("`render_time`")
    assert rows["a BVH's frame time grows with the triangle count"].rows.startswith("`render_shapes`")


@pytest.mark.parametrize("change,claim,before,after", [
    ({"ablation": ablation({"s_fc": 0.1e-3, "s_dr": 0.95e-3, "s_p": 0.2e-3})}, "s_p matters more than s_fc",
     claims.CONFIRMED, claims.REFUTED),
    ({"ablation": ablation({"s_fc": 0.2e-3, "s_dr": 0.95e-3, "s_p": 0.2e-3})}, "s_p matters more than s_fc",
     claims.CONFIRMED, claims.NOT_SEPARABLE),
    ({"sampling": sampling({"surface": 5e-4, "pov": 3e-4, "random": 9e-4})}, "surface beats pov at equal counts",
     claims.CONFIRMED, claims.REFUTED),
    ({"paper_ddf": [rec("paper_ddf", "ddf_paper_lr", s, jitter(s, 0.3e-3), family="ddf") for s in SEEDS]},
     "ddf_paper_lr: bunny chamfer at most the paper's 0.589×10³", claims.NO_RECORDS, claims.NOT_TESTABLE),
    ({"paper_ddf": [{**rec("paper_ddf", "ddf_paper", s, 8.64, family="ddf"), "fit": {"steps": 292},
                     "metrics": {"chamfer_l2": 8.64, "empty_reconstruction": True, "n_points": 2000}} for s in SEEDS]},
     "ddf_paper: bunny chamfer at most the paper's 0.589×10³", claims.NO_RECORDS, claims.NOT_CONVERGED),
    ({"paper_ddf": [{**rec("paper_ddf", "ddf_paper", s, 0.2, family="ddf"), "fit": {"steps": 292},  # a blob off the shape
                     "metrics": {"chamfer_l2": 0.2, "fscore": {"0.02": 0.0}, "n_points": 2000}} for s in SEEDS]},
     "ddf_paper: bunny chamfer at most the paper's 0.589×10³", claims.NO_RECORDS, claims.NOT_CONVERGED),
    ({"representations": representations(1.05)}, "DDF as accurate as the neural SDF", claims.REFUTED,
     claims.CONFIRMED),
    ({"render_time": render_time("cuda")}, f"DDF renders faster than {claims.SDF}", claims.NOT_TESTABLE, claims.CONFIRMED),
    ({"render_time": render_time("cuda")}, "DDF renders faster than mesh", claims.NOT_TESTABLE, claims.REFUTED),
    ({"render_time": render_time("cuda")}, "DDF's first frame slower than its warm frames", claims.NOT_TESTABLE,
     claims.CONFIRMED),
    ({"render_time": render_time("cpu", bvh_growth=0.5)}, "a BVH's frame time grows with the triangle count",
     claims.CONFIRMED, claims.REFUTED),
    ({"render_time": render_time("cpu", normal_ratio=1.05)}, "DDF normals from autograd as accurate as the neural SDF's",
     claims.REFUTED, claims.CONFIRMED),
    ({"storage": storage(2e6)}, "G < mesh < grid SDF in storage", claims.CONFIRMED, claims.REFUTED),
    ({"storage": storage(60e3)}, "the generator G stores in ~47 KB", claims.CONFIRMED, claims.REFUTED),
])
def test_a_verdict_flips_when_the_numbers_do(change, claim, before, after):
    assert verdicts(records())[claim] == before
    assert verdicts(records(**change))[claim] == after


def test_report_command_writes_claims_md(tmp_path):
    for experiment, recs in records().items():
        for r in recs:
            write_json_atomic(str(tmp_path / "results" / experiment / r["key"] / "record.json"), r)
    out = tmp_path / "claims.md"
    assert report_main([str(tmp_path / "results"), "--claims", "--out", str(out)]) == 0
    text = out.read_text()
    assert "python -m ddfbench.report --claims" in text and "(code: abc)" in text
    rows = [line for line in text.splitlines() if line.startswith("| ") and "---" not in line][1:]
    assert len(rows) == len(claims.evaluate(records())) and all(line.count(" | ") == 6 for line in rows)


def test_a_claims_table_without_out_goes_beside_its_records_not_over_the_committed_one(tmp_path, monkeypatch):
    for experiment, recs in records().items():
        for r in recs:
            write_json_atomic(str(tmp_path / "results" / experiment / r["key"] / "record.json"), r)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "reports").mkdir()
    assert report_main(["results", "--claims"]) == 0
    assert (tmp_path / "results" / "claims.md").read_text().startswith("# ")
    assert not (tmp_path / "reports" / "claims.md").exists()
    (tmp_path / "empty").mkdir()  # a folder with no experiment's records: one line, no table of "no records"
    assert report_main(["empty", "--claims"]) == 2 and not (tmp_path / "empty" / "claims.md").exists()


@pytest.mark.parametrize("ratios,verdict", [((0.90, 1.00, 1.05), claims.CONFIRMED), ((0.50, 0.52, 0.48), claims.REFUTED)])
def test_the_papers_effect_size_is_confirmed_only_inside_the_measured_interval(ratios, verdict):
    base = (1.0e-3, 1.1e-3, 0.9e-3)
    recs = [rec("ablation", "ddf", s, base[s], shape="bone", sampling={"s_fc": 10, "s_dr": 10, "s_p": 10}) for s in SEEDS]
    recs += [rec("ablation", "ddf", s, base[s] * ratios[s], shape="bone", sampling={"s_fc": 30, "s_dr": 10, "s_p": 10})
             for s in SEEDS]
    assert verdicts({"ablation": recs})["the paper's effect of s_fc 10→30 (CD ×0.972)"] == verdict


def test_claims_md_names_the_code_commit_not_a_reports_only_head():
    recs = records()
    for r in recs["representations"]:  # HEAD moved by a reports-only commit after the code commit c0de
        r["env"] = {**r["env"], "git_sha": "4ead", "code_sha": "c0de"}
    text = claims.to_markdown(claims.evaluate(recs), recs, "results")
    assert "(code: abc, c0de)" in text and "4ead" not in text


def render_matched(loose_warm_s, device="cuda"):
    """neural_sdf with a loose tracer: depth error 0.015 (below the DDF's 0.02) at loose_warm_s."""
    out = []
    for s in SEEDS:
        r = rec("render_matched", claims.SDF, s, 1e-4, scene={"width": 64, "height": 64}, family="neural_sdf",
                cost={"render_warm_s": loose_warm_s}, device=device)
        r["metrics"]["depth_mae"], r["overrides"] = 0.015, ["++model.trace.eps_abs=3e-3"]
        out.append(r)
    return out


def matched_times(device="cuda"):
    """render_time's records with depth errors: the DDF 0.02, the SDF 0.001 (tracer at its default), the mesh 0 and
    slower than the DDF (the matched verdict hangs on the neural SDF)."""
    times = [r for r in render_time(device) if r["model"] != "mesh_lod2000"]
    for r in times:
        r["scene"]["height"] = 64
        r["metrics"]["depth_mae"] = {claims.DDF: 0.02, claims.SDF: 0.001, "mesh": 0.0}[r["model"]]
        if r["model"] == "mesh":
            r["cost"]["render_warm_s"] = 0.5
    return times


def test_matched_depth_error_row_follows_the_loosened_tracer():
    claim = "DDF renders faster at matched accuracy"
    assert verdicts(records(render_time=matched_times(), render_matched=render_matched(0.05)))[claim] == claims.REFUTED
    assert verdicts(records(render_time=matched_times(), render_matched=render_matched(0.2)))[claim] == claims.CONFIRMED
    assert verdicts(records(render_time=matched_times("cpu"), render_matched=render_matched(0.2, "cpu")))[claim] == \
        claims.NOT_TESTABLE


def test_the_matched_render_claim_reads_the_device_of_its_own_records():
    claim = "DDF renders faster at matched accuracy"
    cuda = records(render_time=matched_times(), render_matched=render_matched(0.2),
                   render_shapes=render_shapes((0.2, 0.3, 0.25, 0.4)))  # CPU frames over shapes beside them
    assert verdicts(cuda)[claim] == claims.CONFIRMED
    cpu = records(render_time=matched_times("cpu"), render_matched=render_matched(0.2, "cpu"),
                  render_shapes=render_shapes((0.2, 0.3, 0.25, 0.4), device="cuda"))
    assert verdicts(cpu)[claim] == claims.NOT_TESTABLE


def test_the_models_the_claims_compare_are_those_the_experiments_run():
    """claims.DDF / claims.SDF and the render_matched reference name the presets representations and
    render_time sweep (a renamed or dropped preset would leave the claims without records)."""
    from hydra import compose, initialize_config_dir

    from ddfbench.core import plugins
    from ddfbench.core.plugins import CONF_DIR
    from ddfbench.report import matched

    for experiment in ("representations", "render_time"):
        assert {claims.DDF, claims.SDF} <= set(plugins.members("model", experiment)), experiment
    assert matched.REFERENCE == claims.DDF and "mesh" in plugins.members("model", "render_time")
    assert {"ddf_paper", "ddf_paper_lr"} == set(plugins.members("model", "paper_ddf"))
    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        cfg = compose("config", overrides=["+experiment=render_matched"], return_hydra_config=True)
    assert claims.SDF in str(cfg.hydra.sweeper.params.model).split(",")


def test_claims_without_records_keep_their_previous_rows_marked_and_the_others_are_recomputed(tmp_path):
    def write(recs, folder):
        for experiment, rs in recs.items():
            for r in rs:
                write_json_atomic(str(tmp_path / folder / experiment / r["key"] / "record.json"), r)

    write(records(), "all")
    previous = tmp_path / "claims.md"
    assert report_main([str(tmp_path / "all"), "--claims", "--out", str(previous)]) == 0
    # the sampling sweep rerun elsewhere, by code "new", and now pov is worse than random
    flipped = sampling({"surface": 1e-4, "pov": 9e-4, "random": 3e-4})
    for r in flipped:
        r["env"]["git_sha"] = "new"
    write({"sampling": flipped}, "rerun")
    out = tmp_path / "claims2.md"
    assert report_main([str(tmp_path / "rerun"), "--claims", "--out", str(out), "--carry", str(previous)]) == 0
    before, _ = claims.read_table(previous.read_text())
    after, codes = claims.read_table(out.read_text())
    assert [c.claim for c in after] == [c.claim for c in before]  # no row lost, none added, same order
    marked = {line.split(" | ")[0].removeprefix("| † ") for line in out.read_text().splitlines() if line.startswith("| † ")}
    fig6 = {"surface beats pov at equal counts", "pov beats random at equal counts", "surface beats random at equal counts"}
    with_verdict = {c.claim for c in before if c.verdict != claims.NO_RECORDS}
    always = {"GAN more accurate than CNN on 2D SDFs", "airplane chamfer 0.951×10³ (DeepSDF 0.792)",
              "as good with much fewer iterations", "the clamp δ trades surface detail for draw distance",
              "uniform samples fit better than narrow-band ones (2D)",
              "learning rates 1e-4 to 5e-4 make little difference",
              "4 hidden layers clearly better than 3, 5 about as good as 4",
              "Adam rather than SGD for 3D SDFs"}  # rows that need no records: computed every time
    assert marked == with_verdict - fig6 - always  # carried: all but what was rerun
    v0, v1 = {c.claim: c.verdict for c in before}, {c.claim: c.verdict for c in after}
    assert v0["pov beats random at equal counts"] == claims.CONFIRMED and v1["pov beats random at equal counts"] == claims.REFUTED
    assert {k: v for k, v in v1.items() if k not in fig6} == {k: v for k, v in v0.items() if k not in fig6}
    assert codes == ["new", "abc"]  # this run's code, then the carried rows' (the previous table's)
    assert report_main([str(tmp_path / "rerun"), "--claims", "--out", str(out), "--carry", str(tmp_path / "none.md")]) == 2
    (tmp_path / "notes.md").write_text("# notes\n\nno table here\n")
    assert report_main([str(tmp_path / "rerun"), "--claims", "--out", str(out), "--carry", str(tmp_path / "notes.md")]) == 2


def test_the_storage_order_counts_only_a_g_that_gave_a_mesh_and_names_a_smaller_lod():
    empty_g = {**rec("storage", "gan_sdf", 1, 8.0, cost={"storage_bytes": 30e3}),
               "metrics": {"chamfer_l2": 8.0, "empty_reconstruction": True, "n_points": 2000}}
    lod = rec("storage", "mesh_lod500", 0, 4e-5, cost={"storage_bytes": 9.7e3}, family="mesh")
    row = {c.claim: c for c in claims.evaluate({"storage": storage(50e3) + [empty_g, lod]})}["G < mesh < grid SDF in storage"]
    assert row.verdict == claims.CONFIRMED and "G 50.0 kB" in row.measured  # the empty G's 30 kB is not G's size
    assert "smallest mesh LOD is 9.7 kB, below G" in row.measured and "1 G runs gave no mesh or one off the shape" in row.measured
    (only_empty,) = [c for c in claims.evaluate({"storage": storage(50e3)[1:] + [empty_g]})
                     if c.claim == "G < mesh < grid SDF in storage"]
    assert only_empty.verdict == claims.NOT_CONVERGED


def test_the_thesis_summary_rows_read_storage_and_the_40_epoch_gan():
    v = verdicts(records())
    assert v["G under 0.1 % of the grid SDF's storage"] == claims.REFUTED  # 50 kB of 8.4 MB: 0.595 %
    assert verdicts(records(storage=storage(5e3)))["G under 0.1 % of the grid SDF's storage"] == claims.CONFIRMED
    assert v["G's error small against the grid SDF's"] == claims.NO_RECORDS
    grid = [rec("representations", "grid_sdf", s, jitter(s, 1.5e-5), family="grid_sdf") for s in SEEDS]
    for g_cd, spread, verdict in ((2.5e-5, 0.02, claims.CONFIRMED), (1.45e-4, 0.02, claims.REFUTED),
                                  (1.45e-4, 0.9, claims.NOT_SEPARABLE)):  # 1.7x, 9.7x, and 9.7x with a wide spread
        gan = [rec("gan_epochs", "gan_sdf", s, jitter(s, g_cd, spread), family="gan_sdf") for s in SEEDS]
        got = verdicts(records(gan_epochs=gan, representations=representations(3.0) + grid))
        assert got["G's error small against the grid SDF's"] == verdict, (g_cd, spread)
    one = [rec("gan_epochs", "gan_sdf", 0, 1.5e-4, family="gan_sdf")]  # one run: no interval, not separable
    (row,) = [c for c in claims.evaluate(records(gan_epochs=one, representations=representations(3.0) + grid))
              if c.claim == "G's error small against the grid SDF's"]
    assert row.verdict == claims.NOT_SEPARABLE and "10× (no interval" in row.measured
    assert row.measured.endswith("; 2000 points")  # the records' evaluation point count


def test_a_grid_sdf_run_in_two_experiments_counts_once():
    """The shape suite's bunny runs of the grid SDF are the representations runs of the same keys: pooled, each is
    one run (n 3, not 6)."""
    grid = [rec("representations", "grid_sdf", s, jitter(s, 1.5e-5), family="grid_sdf") for s in SEEDS]
    again = [{**r, "experiment": "shape_suite"} for r in grid]
    gan = [rec("gan_epochs", "gan_sdf", s, jitter(s, 1.45e-4), family="gan_sdf") for s in SEEDS]
    (row,) = [c for c in claims.evaluate(records(gan_epochs=gan, representations=grid, shape_suite=again))
              if c.claim == "G's error small against the grid SDF's"]
    assert "(n=3): ratio" in row.measured and "(n=6)" not in row.measured


def test_a_paper_network_row_says_how_many_of_its_runs_gave_no_result():
    runs = [rec("paper_ddf", "ddf_paper_lr", s, jitter(s, 0.3e-3), family="ddf") for s in SEEDS]
    runs[1] = {**runs[1], "metrics": {"chamfer_l2": 0.0864, "fscore": {"0.02": 0.0}, "n_points": 2000}}  # off the shape
    (row,) = [c for c in claims.evaluate(records(paper_ddf=runs))
              if c.claim == "ddf_paper_lr: bunny chamfer at most the paper's 0.589×10³"]
    assert "with 1 of 3 runs empty or off the shape (their chamfer in the mean)" in row.measured
    assert row.verdict == claims.NOT_TESTABLE


def test_holm_notes_count_the_comparisons_that_have_a_p():
    assert claims._holm_note([0.02, float("nan"), 0.04]) == ["; p 0.02, Holm 0.04 (2 comparisons)", "; p –",
                                                            "; p 0.04, Holm 0.04 (2 comparisons)"]


def grid_encodings(grid_gap, mlp_gap=10.0):
    """The DDF at grid_gap x the grid SDF's chamfer and mlp_gap x the MLP SDF's, on three shapes (a spread by shape)."""
    out = []
    for shape, base in (("bunny", 1e-5), ("cup", 3e-5), ("chain", 2e-5)):
        spread = {"bunny": 1.0, "cup": 1.1, "chain": 0.9}[shape]
        for model, family, cd in ((claims.GRID_DDF, "ddf", base * grid_gap * spread), (claims.GRID_SDF, "neural_sdf", base),
                                  (claims.DDF, "ddf", 3 * base * mlp_gap / spread), (claims.SDF, "neural_sdf", 3 * base)):
            out += [rec("grid_encodings", model, s, jitter(s, cd), shape=shape, family=family) for s in SEEDS]
    return out


@pytest.mark.parametrize("grid_gap,verdict", [(1.1, claims.CONFIRMED), (8.0, claims.REFUTED)])
def test_the_same_encoding_row_asks_whether_the_grid_pair_is_as_accurate(grid_gap, verdict):
    (row,) = [c for c in claims.evaluate({"grid_encodings": grid_encodings(grid_gap)})
              if c.claim == "the DDF's gap to the SDF closes with the same encoding"]
    assert row.verdict == verdict
    # per shape the grid ratio is grid_gap x (1, 1.1, 0.9) and the MLP ratio 10 / (1, 1.1, 0.9)
    assert f"{claims.GRID_DDF}/{claims.GRID_SDF} {grid_gap * (1.1 * 0.9) ** (1 / 3):.3g}×" in row.measured
    assert "(n=3 shapes)" in row.measured
    # grid ratio / MLP ratio per shape: grid_gap s / (10 / s) for s in (1, 1.1, 0.9)
    closed = grid_gap / 10 * (1.1 ** 2 * 0.9 ** 2) ** (1 / 3)
    assert f"grid ratio / MLP ratio {closed:.3g}×" in row.measured
    assert verdicts({})["the DDF's gap to the SDF closes with the same encoding"] == claims.NO_RECORDS


def test_the_gpu_race_claims_read_the_committed_repeats_file(tmp_path):
    """reports/bench/cuda/h200/repeats.json (bench.repeats) gives the GPU rows: geometric mean over runs with the
    t interval of the logs, confirmed only when both ray sets lie above 1; no file: no records."""
    import json
    import os

    from ddfbench.report import claims as cl

    def row(q, values, geometric=None):  # a pooled row as bench.repeats writes it; a ratio with (gmean, glo, ghi)
        g = dict(zip(("gmean", "glo", "ghi"), geometric)) if geometric else {}
        return {"quantity": q, "n": len(values), "values": {str(i): v for i, v in enumerate(values, 1)}, "median": 0,
                **g}

    rows = [row("primary: DDF / warp_bvh", [2.0, 4.0, 3.0], (2.88, 1.51, 5.49)),
            row("incoherent: DDF / warp_bvh", [3.0, 3.5, 4.0], (3.48, 2.42, 5.0)),
            row("primary: DDF / neural SDF device tracer", [0.5, 2.0, 1.0], (1.0, 0.18, 5.6)),
            row("incoherent: DDF / neural SDF device tracer", [300.0, 320.0, 310.0], (310, 289, 333))]
    path = tmp_path / cl.GPU_RACE_FILE
    os.makedirs(path.parent)
    rows += [row("capacity c2 (128x4): DDF / mesh_lod_1000", [1.0, 1.2, 0.9], (1.03, 0.72, 1.47)),
             row("capacity c2 (128x4): DDF / mesh_lod_4000", [1.5, 1.4, 1.6], (1.5, 1.27, 1.76)),
             row("capacity c1 (64x3): DDF / mesh_lod_1000", [1.9], (1.9, 1.9, 1.9)),  # c1's coarsest LOD in one run
             row("capacity c1 (64x3): DDF / mesh_lod_4000", [2.5, 2.4], (2.45, 2.0, 3.0)),
             {**row("capacity c1 (64x3): depth MAE", [0.03] * 2), "median": 0.03},
             {**row("capacity c2 (128x4): depth MAE", [0.02] * 3), "median": 0.02},
             {**row("mesh_lod_1000: depth MAE (primary)", [0.004] * 3), "median": 0.004},
             {**row("primary: depth MAE DDF", [0.02] * 3), "median": 0.02}]
    path.write_text(json.dumps({"rows": rows, "gpu": ["GPU X"], "runs": ["a", "b", "c"], "commits": ["abc1234"] * 3}))
    out = {c.claim: c for c in cl.renders_faster_on_gpu(cl.load_committed(str(tmp_path)))}
    bvh = out["DDF renders faster than a GPU BVH (Warp)"]
    assert bvh.verdict == cl.CONFIRMED  # both intervals above 1
    assert "primary rays 2.88× [1.51, 5.49] (n=3 runs); incoherent rays 3.48× [2.42, 5] (n=3 runs)" in bvh.measured
    assert "GPU X, 3 fresh processes, code abc1234" in bvh.rows
    # the coarsest LOD beside capacity c2 measured twice or more, at 0.02 / 0.004 = 5x the LOD's depth error
    assert "c2 (128x4) / the 1000-triangle LOD 1.03× [0.72, 1.47] (n=3) at 5× the LOD's" in bvh.convention
    assert "4000-triangle" not in bvh.convention and "c1 (64x3)" not in bvh.convention  # one run: not quoted
    assert out["DDF renders faster than the neural SDF, sphere traced on the GPU"].verdict == cl.NOT_SEPARABLE
    assert out["DDF renders faster than the grid SDF, sphere traced on the GPU"].verdict == cl.NO_RECORDS
    # a file pooled by older code (no geometric columns) reads as no records, not a crash
    rows[0] = {k: v for k, v in rows[0].items() if k not in ("gmean", "glo", "ghi")}
    path.write_text(json.dumps({"rows": rows, "gpu": ["GPU X"], "runs": ["a", "b", "c"], "commits": ["abc1234"] * 3}))
    old = {c.claim: c for c in cl.renders_faster_on_gpu(cl.load_committed(str(tmp_path)))}
    assert old["DDF renders faster than a GPU BVH (Warp)"].verdict == cl.NO_RECORDS
    assert all(c.verdict == cl.NO_RECORDS for c in cl.renders_faster_on_gpu(cl.load_committed(str(tmp_path / "none"))))


def test_the_plateau_row_gives_how_far_the_gan_s_error_fell_between_its_last_two_probes():
    def gan(seed, fell_to, before=4e-4, widest_f=0.9):
        r = rec("gan_epochs", "gan_sdf", seed, 1e-4, family="gan_sdf")
        r["metrics"]["fscore"] = {"0.02": widest_f}
        r["config"]["train"] = {"probe_points": 30000}
        r["fit"] = {"steps": 3000, "epochs": 40.0, "probes": [  # out of step order, as a resumed fit may write them
            {"step": 3000, "chamfer_l2": 4e-4 * fell_to}, {"step": 300, "chamfer_l2": 1e-2},
            {"step": 1000, "chamfer_l2": before}]}
        return r

    def row(recs):
        return next(c for c in claims.evaluate(records(gan_epochs=recs)) if "plateau" in c.claim)

    assert row([]).verdict == claims.NO_RECORDS and row([]).measured == "–"
    halved = row([gan(s, jitter(s, 0.5)) for s in SEEDS])
    assert halved.verdict == claims.NOT_TESTABLE  # no probe after the 40th epoch
    assert "(epochs 13.3 to 40, probes on 30000 points): 0.5× [" in halved.measured
    assert halved.measured.endswith("(n=3 runs)")
    assert "(epochs 13.3 to 40, probes on 30000 points): 0.9× [" in row([gan(s, jitter(s, 0.9)) for s in SEEDS]).measured
    vanished = [gan(s, 0.5) for s in SEEDS[:2]] + [gan(2, 0.5, before=8.64)]  # no surface at 13.3 epochs: the penalty
    assert row(vanished).measured.endswith("0.5× [0.5, 0.5] (n=2 runs); 1 run left out "
                                           "(a probe without a surface or an epoch count)")
    failed = row([gan(s, 0.5, widest_f=0.0) for s in SEEDS])  # every final mesh off the shape
    assert failed.verdict == claims.NOT_TESTABLE and failed.measured == "no run gave a result"


def test_the_ddf_mesh_frame_ratio_names_the_all_core_bvh_of_suite_v1_records():
    from ddfbench.report.claims import DDF, _all_core_bvh

    def rec(cost):
        return {"model": DDF, "config": {"oracle": {"backend": "open3d"}}, "env": {"cpu_count": 16},
                "cost": {"render_threads": 1, **cost}}

    note = _all_core_bvh([rec({})])
    assert "every core (16, open3d's default), the DDF on 1 thread(s)" in note and "erratum" in note
    assert _all_core_bvh([rec({"reference_threads": 1})]) == ""  # records of the fixed code say what the BVH used
    assert _all_core_bvh([{**rec({}), "config": {"oracle": {"backend": "embree"}}}]) == ""


def test_below_needs_the_whole_interval_on_one_side_and_the_holm_p():
    """below(s, bound): confirmed only when the interval's upper end is below the bound, refuted when its lower end is
    above, else not separable; with p_holm a side also needs p_holm < 0.05 (the raw interval can clear the bound
    while the family's correction does not). Kills judging by the lower end alone and dropping the Holm gate, which
    the ordering claims' synthetic records (all far from the bound) let through."""
    from ddfbench.report.stats import Summary

    clear, straddles, above = (Summary(-1.0, 0.3, 3, -2.0, -0.5), Summary(-0.5, 0.5, 3, -2.0, 0.5),
                               Summary(1.0, 0.3, 3, 0.5, 2.0))
    assert claims.below(clear, 0.0) == claims.CONFIRMED
    assert claims.below(straddles, 0.0) == claims.NOT_SEPARABLE
    assert claims.below(above, 0.0) == claims.REFUTED
    assert claims.below(clear, 0.0, p_holm=0.01) == claims.CONFIRMED
    assert claims.below(clear, 0.0, p_holm=0.06) == claims.NOT_SEPARABLE  # raw interval clear, Holm p not
    assert claims.below(above, 0.0, p_holm=0.06) == claims.NOT_SEPARABLE
    assert claims.below(Summary(-1.0, float("nan"), 1, float("nan"), float("nan")), 0.0) == claims.NOT_SEPARABLE


def test_as_accurate_needs_the_whole_ratio_interval_at_or_below_the_equivalence_bound():
    """'As accurate' (ratio a/b at most EQUIVALENCE = 1.5): an interval reaching above 1.5 is not separable even when
    its centre is below; at the bound exactly counts; wholly above is refuted; a Holm p of 0.05 or more leaves either
    side unjudged. Kills judging by the centre, which the two extreme synthetic cases (1.05, 8.0) let through."""
    from ddfbench.report.across_shapes import OverShapes

    assert claims.EQUIVALENCE == 1.5
    assert claims._as_accurate(OverShapes(1.2, 1.0, 1.5, 3)) == claims.CONFIRMED
    assert claims._as_accurate(OverShapes(1.3, 1.1, 1.8, 3)) == claims.NOT_SEPARABLE
    assert claims._as_accurate(OverShapes(2.0, 1.6, 2.5, 3)) == claims.REFUTED
    assert claims._as_accurate(OverShapes(1.2, 1.0, 1.4, 3), p_holm=0.2) == claims.NOT_SEPARABLE
    assert claims._as_accurate(OverShapes(2.0, 1.6, 2.5, 3), p_holm=0.01) == claims.REFUTED
    assert claims._as_accurate(OverShapes(1.2, float("nan"), float("nan"), 1)) == claims.NOT_SEPARABLE


def test_the_bvh_claim_takes_its_capacities_from_their_own_repeats_where_committed(tmp_path):
    """With bench/cuda/h200_capacities/repeats.json committed, the BVH row quotes every capacity against the BVH
    raced beside it (two runs or more), names the most accurate one whose interval lies above 1, and takes the
    matched-accuracy LOD note from those runs, not from the race's own capacity rows."""
    import json
    import os

    from ddfbench.report import claims as cl

    def row(q, values, geometric=None, median=0.0):
        g = dict(zip(("gmean", "glo", "ghi"), geometric)) if geometric else {}
        return {"quantity": q, "n": len(values), "values": {str(i): v for i, v in enumerate(values, 1)},
                "median": median, **g}

    race = [row("primary: DDF / warp_bvh", [2.0, 4.0, 3.0], (2.88, 1.51, 5.49)),
            row("incoherent: DDF / warp_bvh", [3.0, 3.5, 4.0], (3.48, 2.42, 5.0)),
            row("primary: depth MAE DDF", [0.02] * 3, median=0.02),
            row("capacity c2 (128x4): DDF / mesh_lod_1000", [1.0, 1.2], (1.1, 0.5, 2.4)),
            row("capacity c2 (128x4): depth MAE", [0.02] * 2, median=0.02),
            row("mesh_lod_1000: depth MAE (primary)", [0.004] * 2, median=0.004)]
    caps = [row("capacity c1 (64x3): DDF / warp_bvh", [4.0, 5.0, 4.5], (4.5, 3.9, 5.2)),
            row("capacity c1 (64x3): depth MAE", [0.03] * 3, median=0.03),
            row("capacity c2 (128x4): DDF / warp_bvh", [3.0, 3.2, 2.8], (3.0, 2.5, 3.6)),
            row("capacity c2 (128x4): depth MAE", [0.018] * 3, median=0.018),
            row("capacity c3 (256x6): DDF / warp_bvh", [0.5, 1.1, 0.8], (0.76, 0.3, 1.9)),
            row("capacity c3 (256x6): depth MAE", [0.015] * 3, median=0.015),  # more accurate, not faster
            row("capacity c4 (512x6): DDF / warp_bvh", [0.2], (0.2, 0.2, 0.2)),  # one run: not quoted
            row("capacity c2 (128x4): DDF / mesh_lod_1000", [0.9, 1.0, 1.1], (0.99, 0.75, 1.3)),
            row("mesh_lod_1000: depth MAE (primary)", [0.003] * 3, median=0.003)]
    doc = {"gpu": ["GPU X"], "runs": ["a", "b", "c"]}
    for name, rows, commit in ((cl.GPU_RACE_FILE, race, "abc1234"), (cl.GPU_CAPACITIES_FILE, caps, "def5678")):
        path = tmp_path / name
        os.makedirs(path.parent)
        path.write_text(json.dumps({**doc, "rows": rows, "commits": [commit] * 3}))
    bvh = {c.claim: c for c in cl.renders_faster_on_gpu(cl.load_committed(str(tmp_path)))}[
        "DDF renders faster than a GPU BVH (Warp)"]
    assert "h200_capacities/repeats.md` (GPU X, 3 fresh processes, code def5678)" in bvh.convention
    assert "c1 (64x3) 4.5× [3.9, 5.2]; c2 (128x4) 3× [2.5, 3.6]; c3 (256x6) 0.76× [0.3, 1.9] (" in bvh.convention
    assert "c4 (512x6)" not in bvh.convention
    assert "the most accurate whose interval lies above 1: c2 (128x4), depth MAE 0.018" in bvh.convention
    assert "c2 (128x4) / the 1000-triangle LOD 0.99× [0.75, 1.3] (n=3) at 6× the LOD's" in bvh.convention
    assert "1.1× [0.5, 2.4]" not in bvh.convention  # the race's own capacity row is not quoted
