"""`python -m ddfbench.bench` at the tiniest sizes: the outputs' structure, ratios that are finite,
positive and consistent with the figures beside them. No timing assertions."""

import importlib.util
import json
import math
import os
import platform
import time

import pytest
import torch

from ddfbench.bench import CUDA_ONLY_BY_DEFAULT, ON_REQUEST, SECTIONS, render_time
from ddfbench.bench.__main__ import main
from ddfbench.bench.results import Target, compare
from ddfbench.bench.timing import measure, measure_side_by_side, precision_context
from ddfbench.evaluate.trace import TraceOptions


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    code = main(["--sizes", "small", "--repeats", "2", "--warmup", "0", "--out", str(out)])
    doc = json.loads((out / "bench-cpu-small.json").read_text())
    return code, doc, (out / "bench-cpu-small.md").read_text()


@pytest.mark.slow
def test_every_section_runs_and_every_ratio_is_finite_positive(small_run):
    code, doc, _ = small_run
    assert code == 0
    assert list(doc["sections"]) == [s for s in SECTIONS if s not in CUDA_ONLY_BY_DEFAULT + ON_REQUEST]
    assert doc["env"]["device"] == "cpu" and doc["env"]["threads"] >= 1
    for name, sec in doc["sections"].items():
        assert sec["error"] is None, (name, sec["error"])
        assert sec["rows"] and sec["notes"] == [], (name, sec["notes"])
        for r in sec["rows"]:
            assert r["section"] == name and r["device"] and r["precision"] == "fp32"
            assert math.isfinite(r["ratio"]) and r["ratio"] > 0, r
            assert r["value"] > 0 and r["reference_value"] > 0, r
            num, den = ((r["reference_value"], r["value"]) if r["ratio_means"] == "reference / value"
                        else (r["value"], r["reference_value"]))
            assert r["ratio"] == pytest.approx(num / den, rel=1e-9)
            assert (r["target"] is None) == (r["met"] is None)


@pytest.mark.slow
def test_each_issue_comparison_is_present(small_run):
    _, doc, _ = small_run
    rows = {name: [r["measure"] + " | " + r["reference"] for r in sec["rows"]] for name, sec in doc["sections"].items()}
    assert any("open3d cast_rays" in r for r in rows["sampling"])
    for backend in ("open3d", "embree") + (("warp",) if importlib.util.find_spec("warp") else ()):
        for kind in ("primary", "incoherent"):
            assert any(f"backend {backend}, {kind}" in r for r in rows["oracle"])
    for what in ("distance + visibility |", "+ normals |"):
        assert any(what in r and "bare network" in r for r in rows["ddf"])
        assert any(what in r and "Embree" in r for r in rows["ddf"])
    for family in ("neural_sdf", "grid_sdf"):
        assert any(r.startswith(f"{family}: field evaluations") for r in rows["tracing"])
    assert len(rows["grid"]) == 2 and len(rows["metrics"]) == 2
    assert {r.split(":")[0] for r in rows["training"]} == {"ddf", "neural_sdf", "gan_sdf"}
    assert any(": fit seconds" in r for r in rows["end_to_end"])
    assert rows["field_cost"][:2] == [f"gan_sdf generator as matrix products, {c} points a call: points/s | the same "
                                      f"generator through its Conv1d module, {c} points a call" for c in (64, 256)]
    assert all(r.endswith("neural_sdf_tuned field, 65536 points a call, points/s") for r in rows["field_cost"][2:4])
    assert all("dense fp32 matrix product" in r for r in rows["field_cost"][4:]) and len(rows["field_cost"]) == 6
    assert rows["gan_train"] == ["gan_sdf G+D forward and backward, batch 16, pools as Stride1MaxPool1d: samples/s | "
                                 "the same pass with torch's nn.MaxPool1d, samples/s"]
    assert doc["env"]["glibc_heap_kept"] is (platform.libc_ver()[0] == "glibc")
    assert not any(": sampling seconds" in r for r in rows["end_to_end"])  # the small run is a mesh: no samples


@pytest.mark.slow
def test_details_agree_with_what_was_measured(small_run):
    _, doc, _ = small_run
    s = doc["sections"]
    for key, d in s["tracing"]["details"].items():
        # the naive loop evaluates every ray twice per step for max_steps steps
        assert d["naive_evals"] == 2 * TraceOptions().max_steps * d["rays"], key
        assert 0 < d["tracer_evals"] < d["naive_evals"]
        # the tracer's host round trips: 2 at the start, then 2 or 3 a step (tests/test_trace.py)
        assert 4 <= d["tracer_host_syncs"] <= 2 + 3 * TraceOptions().max_steps
    for key, d in s["grid"]["details"].items():
        h = 2 * 0.6 / (int(key.split("=")[1]) - 1)
        assert d["errors"]["max_err_band"] <= h  # the band is exact: only sign errors could reach it
    for d in s["end_to_end"]["details"].values():
        assert d["failed_jobs"] == 0 and d["jobs"] == 1
        assert sum(d["stages_s"].values()) == pytest.approx(d["wall"]["median_s"], rel=1e-6)
    assert s["ddf"]["details"]["ddf_fp32_normals=True"]["hit_share"] == 1.0  # every ray made a hit


@pytest.mark.slow
def test_markdown_has_a_table_row_per_json_row(small_run):
    _, doc, md = small_run
    for i, (name, sec) in enumerate(doc["sections"].items(), 1):
        assert f"## {i}. {name}" in md
    n_rows = sum(len(sec["rows"]) for sec in doc["sections"].values())
    table_lines = [line for line in md.splitlines() if line.startswith("| ") and not line.startswith("| measure")]
    assert len(table_lines) == n_rows
    assert "device **cpu**" in md and "torch threads" in md


def test_bad_options_are_refused(tmp_path, capsys):
    assert main(["--only", "sampling,nonsense", "--out", str(tmp_path)]) == 2
    assert "nonsense" in capsys.readouterr().err
    assert main(["--repeats", "0", "--out", str(tmp_path)]) == 2
    assert main(["--set", "race.no_such_key=1", "--out", str(tmp_path)]) == 2
    assert "race.no_such_key" in capsys.readouterr().err
    assert main(["--device", "tpu", "--out", str(tmp_path)]) == 2
    assert "--device 'tpu': unknown device" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--sizes", "huge"])
    assert not list(tmp_path.iterdir())


def test_some_sections_go_to_their_own_folder_and_an_out_that_is_a_file_is_refused_first(tmp_path, monkeypatch,
                                                                                           capsys):
    """--only without --out writes reports/bench/<sections>: a part never replaces the committed whole bench."""
    from ddfbench.bench.sizes import SIZES

    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(SIZES["small"]["grid"], "shape", "no_such_shape")  # fails at once: nothing is timed
    assert main(["--sizes", "small", "--only", "grid", "--repeats", "1"]) == 1
    assert sorted(os.listdir(tmp_path / "reports" / "bench")) == ["grid"]
    assert (tmp_path / "reports" / "bench" / "grid" / "bench-cpu-small.json").is_file()
    (tmp_path / "afile").write_text("")
    assert main(["--sizes", "small", "--only", "grid", "--out", str(tmp_path / "afile")]) == 2
    assert capsys.readouterr().err.endswith(f"ddfbench.bench: --out {tmp_path / 'afile'}: exists and is not a folder\n")


def test_a_failing_section_is_reported_and_the_exit_code_says_so(tmp_path, monkeypatch):
    from ddfbench.bench.sizes import SIZES

    monkeypatch.setitem(SIZES["small"]["grid"], "shape", "no_such_shape")
    assert main(["--sizes", "small", "--only", "grid,metrics", "--repeats", "1", "--out", str(tmp_path)]) == 1
    doc = json.loads((tmp_path / "bench-cpu-small.json").read_text())
    assert "no_such_shape" in doc["sections"]["grid"]["error"] and not doc["sections"]["grid"]["rows"]
    assert doc["sections"]["metrics"]["error"] is None and doc["sections"]["metrics"]["rows"]
    assert "**failed**" in (tmp_path / "bench-cpu-small.md").read_text()


def test_measure_counts_calls_and_takes_the_median():
    calls = []
    first, t = measure(lambda: calls.append(len(calls)) or len(calls), repeats=5, warmup=2)
    assert first == 1 and len(calls) == 8 and len(t.runs_s) == 5
    ordered = sorted(t.runs_s)
    assert t.median_s == ordered[2] and t.iqr_s >= 0 and t.threads == torch.get_num_threads()
    assert t.rate(10) == pytest.approx(10 / t.median_s)


def test_side_by_side_interleaves_figure_and_reference():
    order = []
    timed = measure_side_by_side({"a": lambda: order.append("a"), "b": lambda: order.append("b")}, repeats=3, warmup=1)
    # cold calls, then a warm-up round and 3 timed rounds, each calling both, the order rotating
    assert order == ["a", "b", "a", "b", "b", "a", "a", "b", "b", "a"]
    assert all(len(t.runs_s) == 3 for _, t in timed.values())


def test_render_time_interleaves_representations_and_times_the_first_render_apart(monkeypatch):
    calls = []

    def fake_render(rep, scene, passes, seed):
        calls.append(rep)
        time.sleep(0.03 if rep == "slow" else 0.001)
        return None, {"primary_rays": 10, "shadow_rays": 5, "bounce_rays": 1, "field_evals": 40 if rep == "slow" else 0}

    monkeypatch.setattr(render_time, "render", fake_render)
    monkeypatch.setattr(render_time, "plan_passes", lambda scene: [])
    rows = render_time._rows([("fast", 0.5, "fast"), ("slow", 0.7, "slow")], scene=None, renders=4)
    # both cold renders first, then rounds of one render each with the order rotated: neither always goes first
    assert calls == ["fast", "slow", "fast", "slow", "slow", "fast", "fast", "slow"]
    fast, slow = rows
    assert len(fast["seconds"]) == 4  # no untimed warm-up: every render is in the row
    assert fast["render_1_s"] == fast["seconds"][0] and fast["later_median_s"] == sorted(fast["seconds"][1:])[1]
    assert fast["rays"] == 16 and fast["rays_per_s"] == pytest.approx(16 / fast["later_median_s"])
    assert (fast["field_evals"], slow["field_evals"], slow["setup_s"]) == (0, 40, 0.7)
    assert slow["later_median_s"] > fast["later_median_s"]


def test_render_time_command_renders_a_too_large_lod_once_and_refuses_two_models_named_alike(capsys):
    # the cube has 12 faces: every default LOD target (10000, 2000, 500) is the full mesh again
    render_time.main(["--shape", "cube", "--size", "8", "--renders", "2"])
    out = capsys.readouterr()
    rows = [line for line in out.out.splitlines() if line.startswith("| mesh")]
    assert rows == [r for r in rows if "faces=12 |" in r] and len(rows) == 1
    assert "as many faces as an earlier row" in out.err
    with pytest.raises(SystemExit):
        render_time.main(["--shape", "cube", "--model", "ddf=a/run/model.pt", "--model", "ddf=b/run/model.pt"])
    assert "share a family and a run folder name" in capsys.readouterr().err


def test_precision_context_switches_autocast_and_rejects_unknown():
    a = torch.ones(4, 4)
    with precision_context("bf16", "cpu"):
        assert (a @ a).dtype == torch.bfloat16
    with precision_context("fp32", "cpu"):
        assert (a @ a).dtype == torch.float32
    with pytest.raises(ValueError):
        with precision_context("fp8", "cpu"):
            pass


def test_compare_orients_ratios_and_checks_targets():
    r = compare("s", "m", 2.0, "x/s", "ref", 8.0, device="cpu", threads=1, target=Target(">=", 0.3))
    assert r.ratio == 0.25 and r.met is False and r.target == "ratio >= 0.3"
    r = compare("s", "m", 2.0, "evals", "ref", 8.0, device="cpu", threads=1, inverse=True, target=Target(">=", 3))
    assert r.ratio == 4.0 and r.met is True
    r = compare("s", "m", 1.2, "s", "ref", 0.5, device="cpu", threads=1, target=Target("<=", 1.5, on="value"))
    assert r.met is True and r.target == "<= 1.5 s"


def test_flops_per_point_counts_linear_and_conv_multiply_adds():
    from torch import nn

    from ddfbench.bench.field_cost import flops_per_point
    from ddfbench.models.gan_sdf import generator

    mlp = nn.Sequential(nn.Linear(3, 10), nn.ReLU(), nn.Linear(10, 4), nn.Linear(4, 1))
    assert flops_per_point(mlp) == 2 * (30 + 40 + 4)
    assert flops_per_point(mlp.to("meta")) == 2 * (30 + 40 + 4)  # counted on the network's own device
    # the thesis generator: Linear 3->256; Conv1d 1->16, k 7 on 256 (250 out); pool 3 (248); Conv1d 16->32,
    # k 5 (244 out); pool 3 (242); Linear 32*242 -> 1
    macs = 3 * 256 + 16 * 250 * 7 + 32 * 244 * 16 * 5 + 32 * 242
    assert flops_per_point(generator()) == 2 * macs


def test_a_section_stopped_by_sigterm_keeps_what_it_measured(tmp_path, monkeypatch):
    """A timeout's SIGTERM during the race's capacities: the report is still written, with the rows of the
    ray sets and the sweep measured before it, the error saying it was stopped, and the sections after it not run."""
    import os
    import signal

    from ddfbench.bench import race

    def stopped(*args, **kwargs):
        try:  # as a section's own broad handler would (a family that failed): the stop must get through it
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # the handler raises here
        except Exception:
            pass
        return {}

    monkeypatch.setattr(race, "capacities", stopped)
    before = signal.getsignal(signal.SIGTERM)
    assert main(["--sizes", "small", "--only", "metrics,race,gan_train", "--repeats", "1", "--out", str(tmp_path),
                 "--set", "race.sweep=[50]"]) == 1
    assert signal.getsignal(signal.SIGTERM) is before
    doc = json.loads((tmp_path / "bench-cpu-small-race-sweep-50.json").read_text())  # --set names the report
    section = doc["sections"]["race"]
    assert section["error"].startswith("Stopped: SIGTERM")
    measures = [row["measure"] for row in section["rows"]]
    assert any(m.startswith("primary:") for m in measures) and any(m.startswith("sweep ") for m in measures)
    assert not any(m.startswith("capacity") for m in measures)
    sweeps = [m for m in measures if m.startswith("sweep ")]
    assert len(sweeps) == 1 and sweeps[0].startswith("sweep 50 rays")
    assert doc["sizes"]["race"]["sweep"] == [50] and "--set race.sweep=[50]" in doc["command"]
    assert doc["sections"]["metrics"]["rows"] and "gan_train" not in doc["sections"]
