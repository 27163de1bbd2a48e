"""Records travel with the reports: the compact file round-trips, a report rebuilt from it alone equals the one
written from the run folders, and `regenerate --from-records --check` names a committed file that differs."""

import errno
import gzip
import json
import os
import shutil
import statistics

import pytest

from ddfbench.report import compact, index
from ddfbench.report.__main__ import main as report_main
from ddfbench.report.regenerate import differences, reports_with_records
from ddfbench.report.regenerate import main as regenerate_main
from ddfbench.run import runner
from tests.hard_cases.conftest import compose

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """Two finished runs (seeds 0 and 1) of the mesh on the cube and one failed run, in results/single."""
    out = tmp_path_factory.mktemp("results")
    for seed in (0, 1):
        assert runner.run(compose("shape=cube", "model=mesh", f"seed={seed}", out_dir=out))["status"] == "ok"
    assert runner.run(compose("shape=cube", "model=mesh", "eval.n_points=0", out_dir=out))["status"] == "failed"
    return out / "single"


def test_the_compact_file_round_trips_and_is_deterministic(results, tmp_path):
    records = compact.load_records(str(results))
    first = compact.write_compact(records, str(tmp_path / "a.jsonl.gz"))
    again = compact.read_compact(first)
    assert [compact.portable(r) for r in sorted(records, key=lambda r: r["key"])] == \
        [{k: v for k, v in r.items() if k != "_dir"} for r in again]
    assert all(r["_dir"] is None for r in again)
    second = compact.write_compact(list(reversed(again)), str(tmp_path / "b.jsonl.gz"))
    assert open(first, "rb").read() == open(second, "rb").read()


def test_the_compact_file_writes_the_machines_out_dir_as_a_placeholder(results, tmp_path):
    record = {**compact.load_records(str(results))[0], "overrides": ["seed=0", "out_dir=/work/res/x", "shape=cube"]}
    path = compact.write_compact([record], str(tmp_path / "a.jsonl.gz"))
    assert compact.read_compact(path)[0]["overrides"] == ["seed=0", "out_dir=<out_dir>", "shape=cube"]
    assert "/work/res" not in gzip.open(path, "rt").read()


def test_the_compact_file_writes_a_package_samples_install_path_as_its_package_and_file(results, tmp_path):
    """Records of older code named the bunny by the machine's pymeshlab install; today's records name the sample."""
    first = compact.load_records(str(results))[0]
    installed = "/work/main/.venv/lib/python3.11/site-packages/pymeshlab/tests/sample_meshes/rangemaps/face000.ply"
    old = {**first, "shape": {**first["shape"], "name": "range_scan", "source": installed}}
    mine = {**first, "key": "f" * 16, "shape": {**first["shape"], "source": "/home/me/part.ply"}}  # a user's file
    back = {r["key"]: r for r in compact.read_compact(compact.write_compact([old, mine], str(tmp_path / "a.jsonl.gz")))}
    assert back[first["key"]]["shape"] == {**old["shape"], "source": "pymeshlab sample rangemaps/face000.ply"}
    assert back["f" * 16]["shape"]["source"] == "/home/me/part.ply"  # as given: the user named it so


def test_a_line_that_is_not_a_record_is_named_and_left_out(tmp_path, capsys):
    path = tmp_path / "r.jsonl.gz"
    with gzip.open(path, "wt") as fh:
        fh.write('{"status": "ok"}\nnot json\n[1]\n')
    assert compact.read_compact(str(path)) == []
    err = capsys.readouterr().err
    assert err.count(str(path)) == 3 and "line 2: not JSON" in err


def test_a_report_from_no_records_or_a_damaged_file_writes_nothing(tmp_path, capsys):
    """An empty folder, a damaged compact file and an --out that is a file are one line each, and the report folder
    (here a copy of a committed one) keeps every byte."""
    committed = tmp_path / "default"
    shutil.copytree(os.path.join(ROOT, "reports", "default"), committed)
    before = {p.name: p.read_bytes() for p in committed.iterdir() if p.is_file()}
    (tmp_path / "empty").mkdir()
    assert report_main([str(tmp_path / "empty"), "--out", str(committed)]) == 2
    assert capsys.readouterr().err == f"ddfbench.report: {tmp_path / 'empty'}: no run records: nothing written\n"
    good = committed / compact.FILE
    lines = gzip.decompress(good.read_bytes()).decode().splitlines()
    with gzip.open(good, "wt") as fh:
        fh.write("\n".join(["not json", *lines[1:]]) + "\n")
    damaged = good.read_bytes()
    assert report_main([str(good)]) == 2
    assert "line 1: not JSON" in capsys.readouterr().err and good.read_bytes() == damaged
    good.write_bytes(b"plain text")
    assert report_main([str(good)]) == 2
    assert capsys.readouterr().err.startswith(f"ddfbench.report: {good}: cannot be read as a compact file (")
    good.write_bytes(before[compact.FILE])
    assert report_main([str(good), "--out", str(tmp_path / "empty" / "x")]) == 0  # the file itself reads
    (tmp_path / "afile").write_text("")
    assert report_main([str(good), "--out", str(tmp_path / "afile")]) == 2
    assert "--out" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in committed.iterdir() if p.is_file()} == before
    assert report_main([str(tmp_path / "empty")]) == 2 and not (tmp_path / "empty" / "report").exists()
    capsys.readouterr()
    # a sweep that left no record, outside the claims' experiments: one line each, the command goes on to its end
    (tmp_path / "res" / "smoke").mkdir(parents=True)
    assert regenerate_main(["--report-only", "--only", "smoke", "--results", str(tmp_path / "res"), "--reports",
                            str(tmp_path / "rep")]) == 2
    out = capsys.readouterr()
    assert "smoke: no report:" in out.err and "claims: not written" in out.out
    assert regenerate_main(["--from-records", "--reports", str(committed)]) == 2  # one report, not the folder above
    assert "holds one report's records itself" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in committed.iterdir() if p.is_file()} == before


def test_a_report_that_fails_midway_leaves_its_folder_as_it_was(tmp_path, capsys, monkeypatch):
    """A run's artifact that cannot be drawn (a reconstruction.ply cut short) fails the gallery after the tables
    are made: one line, and the report folder keeps every byte (the tables were written to a scratch folder)."""
    import ddfbench.report.__main__ as report_cli

    committed = tmp_path / "default"
    shutil.copytree(os.path.join(ROOT, "reports", "default"), committed)
    before = {p.name: p.read_bytes() for p in committed.iterdir() if p.is_file()}

    def cut_short(records, out_dir):
        raise ValueError("PLY is unexpected length!")

    monkeypatch.setattr(report_cli, "write_gallery", cut_short)
    assert report_main([str(committed / compact.FILE), "--note", "changed"]) == 2
    assert capsys.readouterr().err == "ddfbench.report: ValueError: PLY is unexpected length!: nothing written\n"
    assert {p.name: p.read_bytes() for p in committed.iterdir() if p.is_file()} == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".report-")]  # no scratch folder left


def test_a_report_rebuilt_from_its_records_equals_the_written_one(results, tmp_path):
    assert report_main([str(results), "--out", str(tmp_path / "rep"), "--plots", "none"]) == 0
    written = tmp_path / "rep"
    assert (written / compact.FILE).is_file() and (written / "sweep_status.md").is_file()
    assert str(tmp_path) not in (written / "sweep_status.md").read_text()  # no machine path
    assert regenerate_main(["--from-records", "--reports", str(tmp_path), "--check"]) == 0
    rebuilt = tmp_path / "rebuilt"
    assert report_main([str(written / compact.FILE), "--out", str(rebuilt), "--plots", "none"]) == 0
    assert differences(str(written), str(rebuilt)) == []


def test_the_check_names_a_hand_edited_table(results, tmp_path, capsys):
    assert report_main([str(results), "--out", str(tmp_path / "rep"), "--plots", "none"]) == 0
    table = tmp_path / "rep" / "table.md"
    table.write_text(table.read_text().replace(" | cube | ", " | cube (edited) | ", 1))
    assert regenerate_main(["--from-records", "--reports", str(tmp_path), "--check"]) == 1
    assert f"{table} differs" in capsys.readouterr().err


def test_the_index_says_which_reports_regenerate_and_a_stale_index_fails_the_check(results, tmp_path, capsys):
    assert report_main([str(results), "--out", str(tmp_path / "rep"), "--plots", "none"]) == 0
    (tmp_path / "old" / "nested").mkdir(parents=True)  # a report whose records stayed on another machine
    (tmp_path / "old" / "nested" / "report.md").write_text(
        "# old\n\n3 run records from `<out_dir>/old` (code: 0123456789abcdef0123456789abcdef01234567)\n")
    readme = str(tmp_path / "none.md")
    assert regenerate_main(["--from-records", "--reports", str(tmp_path), "--readme", readme]) == 0
    rows = {line.split(" | ")[0]: line for line in (tmp_path / "index.md").read_text().splitlines()
            if line.startswith("| [`")}
    code = compact.read_compact(str(tmp_path / "rep" / compact.FILE))[0]["env"]["code_sha"][:7]
    assert rows["| [`rep/`](rep/)"].endswith(f"| – | 3 | {code} | yes |")  # two finished runs and the failed one
    assert rows["| [`old/nested/`](old/nested/)"].endswith("| – | 3 | 0123456 | no: records not committed |")
    text = (tmp_path / "index.md").read_text()
    assert "1 of 2 report folders regenerate" in text and "saved no rows" not in text
    assert "Not regenerating: 1 report of runs whose records stayed on the machine that ran them" in text
    (tmp_path / "old" / "again").mkdir()  # a re-measurement of runs' artifacts
    (tmp_path / "old" / "again" / "table.md").write_text(
        "`python -m ddfbench.report.reevaluate <out_dir>/old --out x`: 3 runs measured again, records of code abcdef0, "
        "measured by code 1234567.\n")
    (tmp_path / "old" / "again" / "table.csv").write_text("model\n")
    assert index.provenance(str(tmp_path / "old" / "again")) == index.Provenance(3, ["abcdef0"], index.ARTIFACTS)
    (tmp_path / "old" / "again" / "table.md").write_text(  # an older tool's line names no commit
        "`python -m ddfbench.report.reevaluate <out_dir>/old --out x`: 18 runs measured again (0 unreadable).\n")
    assert index.provenance(str(tmp_path / "old" / "again")) == index.Provenance(18, [], index.ARTIFACTS)
    shutil.copytree(tmp_path / "rep", tmp_path / "rep2")
    assert regenerate_main(["--from-records", "--reports", str(tmp_path), "--readme", readme]) == 0
    assert "2 of 4 report folders regenerate" in (text := (tmp_path / "index.md").read_text())
    assert ("Not regenerating: 1 re-measurement saved no rows, and the artifacts stay with the runs; "
            "1 report of runs") in text
    shutil.rmtree(tmp_path / "old")  # every folder left regenerates: the index says nothing is missing
    assert regenerate_main(["--from-records", "--reports", str(tmp_path), "--readme", readme]) == 0
    assert "2 of 2 report folders regenerate" in (text := (tmp_path / "index.md").read_text())
    assert "Not regenerating" not in text
    os.remove(tmp_path / "rep2" / compact.FILE)  # its records go: the committed index no longer says what is true
    capsys.readouterr()
    assert regenerate_main(["--from-records", "--reports", str(tmp_path), "--readme", readme, "--check"]) == 1
    assert f"{tmp_path / 'index.md'} differs" in capsys.readouterr().err


def test_a_report_goes_beside_its_records_unless_out_names_a_folder(results):
    assert report_main([str(results), "--plots", "none"]) == 0
    assert (results / "report" / "report.md").is_file()
    shutil.rmtree(results / "report")


def test_every_committed_report_with_records_regenerates():
    reports = os.path.join(ROOT, "reports")
    assert reports_with_records(reports)  # reports/default at least
    assert os.path.isfile(os.path.join(reports, "claims.md"))  # checked too
    assert regenerate_main(["--from-records", "--reports", reports, "--check"]) == 0


def test_the_claims_table_comes_from_the_committed_records_and_a_hand_edit_fails(tmp_path, capsys):
    reports = tmp_path / "reports"
    shutil.copytree(os.path.join(ROOT, "reports", "shape_suite"), reports / "shape_suite")
    assert regenerate_main(["--from-records", "--reports", str(reports), "--readme", str(tmp_path / "none.md")]) == 0
    text = (reports / "claims.md").read_text()
    assert "`python -m ddfbench.report.regenerate --from-records`" in text
    over_shapes = next(line for line in text.splitlines() if line.startswith("| DDF as accurate as the neural SDF, over"))
    # at n = 12 the ratio's interval lies above 1.5 but its Holm p against 1.5 is 0.12: not separable
    assert "(n=12 shapes" in over_shapes and "**not separable at n**" in over_shapes, over_shapes
    assert "| `ablation` | **no records** |" in text  # not committed in this copy: no row is carried from elsewhere
    (reports / "claims.md").write_text(text.replace("**not separable at n**", "**confirmed**", 1))
    assert regenerate_main(["--from-records", "--reports", str(reports), "--readme", str(tmp_path / "none.md"),
                            "--check"]) == 1
    assert f"{reports / 'claims.md'} differs" in capsys.readouterr().err


def test_the_compact_command_packs_a_folder_of_records(results, tmp_path, capsys):
    out = tmp_path / "r.jsonl.gz"
    assert compact.main([str(results), str(out)]) == 0
    assert "wrote 3 records" in capsys.readouterr().out
    assert [r["key"] for r in compact.read_compact(str(out))] == sorted(r["key"] for r in compact.load_records(str(results)))
    assert compact.main([str(tmp_path / "empty"), str(tmp_path / "x.jsonl.gz")]) == 2


def test_restored_records_resume_a_sweep_on_another_machine(results, tmp_path, capsys):
    """A compact file written back as run records: the runner skips its finished runs (no fit, no artifact written);
    a failed or older record, or one whose key is not a run folder, is left out (its run goes again); a record
    already there is never replaced; the report of the folder is the compact file's."""
    records = compact.load_records(str(results))
    ok = [r for r in records if r["status"] == "ok"]
    crafted = [{**ok[0], "key": "../../escaped"}, {**ok[0], "key": "0123456789abcdef", "schema_version": 0}]
    packed = compact.write_compact(records + crafted, str(tmp_path / "r.jsonl.gz"))
    other = tmp_path / "other_machine"
    assert compact.main(["--restore", packed, str(other)]) == 0
    said = capsys.readouterr()
    assert "restored 2 records" in said.out and "key '../../escaped' is not a run folder" in said.err
    assert "schema_version 0, not 1 (a sweep runs it again)" in said.err  # read_compact leaves it out, as reports do
    assert sorted(os.listdir(other / "single")) == sorted(r["key"] for r in ok)  # nothing escaped, no old schema
    assert not (tmp_path / "escaped").exists()
    # the failed record, the old schema, the escaping key
    assert "3 failed, older, misnamed or damaged, left out" in said.out
    assert compact.restore(packed, str(other)) == (0, 2, 3)  # counted, as the message says
    restored = {r["key"]: r for r in compact.load_records(str(other / "single"))}
    seed0 = runner.run(compose("shape=cube", "model=mesh", "seed=0", out_dir=other))
    assert seed0["started"] == restored[seed0["key"]]["started"]
    assert os.listdir(other / "single" / seed0["key"]) == ["record.json"]  # nothing was fit or meshed
    failed = runner.run(compose("shape=cube", "model=mesh", "eval.n_points=0", out_dir=other))
    assert failed["status"] == "failed" and failed["key"] not in restored  # it ran again
    assert report_main([str(other / "single"), "--out", str(tmp_path / "a"), "--plots", "none"]) == 0
    assert report_main([str(results), "--out", str(tmp_path / "b"), "--plots", "none"]) == 0
    assert (tmp_path / "a" / "table.md").read_text() == (tmp_path / "b" / "table.md").read_text()
    assert compact.main(["--restore", str(tmp_path / "none.jsonl.gz"), str(other)]) == 2


def test_a_report_from_a_compact_file_leaves_out_a_record_of_another_schema_as_from_a_folder(results, tmp_path, capsys):
    ok = [r for r in compact.load_records(str(results)) if r["status"] == "ok"]
    unversioned = {k: v for k, v in ok[0].items() if k != "schema_version"}
    packed = compact.write_compact([unversioned, ok[1]], str(tmp_path / "r.jsonl.gz"))
    assert [r["key"] for r in compact.load_records(packed, strict=True)] == [ok[1]["key"]]
    assert "line 1: no schema_version, not 1 (a sweep runs it again)" in capsys.readouterr().err


def test_no_committed_report_names_a_folder_of_the_machine_that_ran_it():
    """Reports and their compact records write the records' folder as <out_dir>; a path such as /work/res/x or /tmp/x
    means nothing on a clone (a device log's virtual environment is written <venv>)."""
    found = []
    for folder, _, files in os.walk(os.path.join(ROOT, "reports")):
        for name in files:
            if name.endswith((".md", ".csv", ".txt", ".json", ".tex", ".log", ".jsonl.gz")):
                opener = gzip.open if name.endswith(".gz") else open
                with opener(os.path.join(folder, name), "rt", encoding="utf-8", errors="replace") as fh:
                    text = fh.read()
                found += [f"{os.path.relpath(os.path.join(folder, name), ROOT)}: {marker}"
                          for marker in ("/work/", "/tmp/", "/home/", "/root/", "/opt/") if marker in text]
    assert not found, found[:10]


def test_the_verdict_block_is_what_the_committed_records_give_and_a_hand_edit_fails(tmp_path):
    from ddfbench.report import verdict

    assert verdict.main(["--reports", os.path.join(ROOT, "reports"), "--readme", os.path.join(ROOT, "README.md"),
                         "--check"]) == 0
    shutil.copytree(os.path.join(ROOT, "reports", "default"), tmp_path / "reports" / "default")
    shutil.copy(os.path.join(ROOT, "reports", "verdict.md"), tmp_path / "reports" / "verdict.md")
    readme = tmp_path / "README.md"
    readme.write_text(open(os.path.join(ROOT, "README.md")).read())
    assert verdict.main(["--reports", str(tmp_path / "reports"), "--readme", str(readme)]) == 0  # without the suite
    table = (tmp_path / "reports" / "verdict.md").read_text()
    assert "`reports/shape_suite`: no records committed" in table and "| ddf_tuned | short: 3,000 steps |" in table
    (tmp_path / "reports" / "verdict.md").write_text(table.replace("| ddf_tuned | short", "| ddf_tuned | shorter"))
    assert verdict.main(["--reports", str(tmp_path / "reports"), "--readme", str(readme), "--check"]) == 1


def test_no_committed_table_holds_an_interval_outside_its_metric_s_range():
    """Every <metric>_ci_lo/_ci_hi of every committed table.csv lies in the metric's range (stats.metric_range):
    no chamfer interval below 0, no F-score interval above 1."""
    import pandas as pd

    from ddfbench.report.stats import metric_range

    outside = []
    for folder, _, files in os.walk(os.path.join(ROOT, "reports")):
        if "table.csv" in files:
            df = pd.read_csv(os.path.join(folder, "table.csv"))
            for col in (c for c in df.columns if c.endswith(("_ci_lo", "_ci_hi"))):
                lo, hi = metric_range(col[:-6])
                values = df[col].dropna()
                if ((values < lo) | (values > hi)).any():
                    outside.append(f"{os.path.relpath(folder, ROOT)}: {col}")
    assert not outside, outside[:10]


def test_the_verdict_s_own_rows_take_their_frames_from_render_time_s_largest_images():
    import copy

    from ddfbench.report import verdict

    short = compact.read_compact(os.path.join(ROOT, "reports", "default", compact.FILE))
    ddf = [r for r in short if r["model"] == "ddf_tuned"]
    frames = []
    for width, warm in ((64, 1.0), (128, 9.99)):
        for r in copy.deepcopy(ddf):
            r["scene"]["width"], r["cost"]["render_warm_s"] = width, warm
            frames.append(r)
    rows = {(r[0], r[1].split(":")[0]): r for r in verdict.rows(short, short, frames)}
    header = verdict.HEADER.index("warm frame s")
    assert rows[("ddf_tuned", "own")][header] == "9.99"  # the 128² frames, not the 64² ones nor the run's own
    assert rows[("ddf_tuned", "short")][header] != "9.99"
    assert rows[("mesh", "own")][header] == "–"  # no render_time record of the mesh here
    for r in frames:  # another preset under the same name (its learning rate changed): not this row's frames
        r["config"]["model"]["lr"] = 2 * r["config"]["model"]["lr"]
    rows = {(r[0], r[1].split(":")[0]): r for r in verdict.rows(short, short, frames)}
    assert rows[("ddf_tuned", "own")][header] == "–"


def test_the_verdict_adds_a_same_grid_row_only_for_a_preset_the_shape_suite_lacks():
    import copy

    from ddfbench.report import verdict

    short = compact.read_compact(os.path.join(ROOT, "reports", "default", compact.FILE))
    grid = []
    for model in ("ddf_tuned", "neural_sdf_grid"):  # ddf_tuned is in the shape suite: its own row stands
        for shape, scale in (("bunny", 1.0), ("cup", 4.0)):
            for r in copy.deepcopy([r for r in short if r["model"] == "ddf_tuned"]):
                r["model"], r["fit"]["steps"], r["shape"]["name"] = model, 3000, shape
                r["metrics"]["chamfer_l2"] *= scale
                grid.append(r)
    frames = copy.deepcopy([r for r in grid if r["model"] == "neural_sdf_grid" and r["shape"]["name"] == "bunny"])
    for r in frames:
        r["experiment"], r["scene"]["width"], r["cost"]["render_warm_s"] = "render_shapes", 128, 7.77
    sets = {verdict.FRAMES: [{**r, "status": "failed"} for r in frames], verdict.OTHER_FRAMES: frames}
    rows = {(r[0], r[1]): r for r in verdict.rows(short, short, verdict.frame_records(sets), grid)}
    row = rows[("neural_sdf_grid", "same grid: 3,000 steps")]
    assert row[verdict.HEADER.index("warm frame s")] == "7.77"  # render_shapes' frames: render_time's all failed
    bunny = statistics.mean(r["metrics"]["chamfer_l2"] for r in grid if r["model"] == "neural_sdf_grid"
                            and r["shape"]["name"] == "bunny")
    assert row[-1].startswith(f"{bunny * 2 * 1e3:.3g} [") and row[-1].endswith("(n 2)")  # geometric mean of x1, x4
    assert not [r for r in rows if r[0] == "ddf_tuned" and r[1].startswith("same grid")]


def test_the_verdict_says_not_converged_only_when_every_bunny_run_gave_no_result_and_counts_shapes_left_out():
    import copy

    from ddfbench.report import verdict

    short = compact.read_compact(os.path.join(ROOT, "reports", "default", compact.FILE))
    suite = compact.read_compact(os.path.join(ROOT, "reports", "shape_suite", compact.FILE))
    suite = [r for r in suite if r["model"] in ("ddf_tuned", "neural_sdf_tuned")]
    short, suite = copy.deepcopy(short), copy.deepcopy(suite)
    ddf_bunny = [r for r in short if r["model"] == "ddf_tuned" and r["shape"]["name"] == "bunny"]
    sdf_bunny = [r for r in short if r["model"] == "neural_sdf_tuned" and r["shape"]["name"] == "bunny"]
    ddf_bunny[0]["metrics"]["empty_reconstruction"] = True  # one of its 3 seeds
    for r in sdf_bunny:
        r["metrics"]["empty_reconstruction"] = True  # every seed
    lost = next(r for r in suite if r["model"] == "ddf_tuned" and r["shape"]["name"] == "cup")
    lost["metrics"]["empty_reconstruction"] = True  # one seed on one shape of the suite
    rows = {(r[0], r[1].split(":")[0]): r for r in verdict.rows(short, suite)}
    assert rows[("ddf_tuned", "short")][2].startswith(f"no result, not ranked (1 of {len(ddf_bunny)} runs")
    assert rows[("neural_sdf_tuned", "short")][2].startswith(f"not converged ({len(sdf_bunny)} of {len(sdf_bunny)}")
    last = verdict.HEADER.index(verdict.HEADER[-1])
    assert rows[("ddf_tuned", "own")][last].endswith("(n 11); 1 shape left out (a run gave no result)")
    assert "left out" not in rows[("neural_sdf_tuned", "own")][last]



def test_a_bunny_run_that_failed_is_counted_in_the_verdict_not_dropped():
    import copy

    from ddfbench.report import verdict

    short = copy.deepcopy(compact.read_compact(os.path.join(ROOT, "reports", "default", compact.FILE)))
    ddf_bunny = [r for r in short if r["model"] == "ddf_tuned" and r["shape"]["name"] == "bunny"]
    ddf_bunny[0]["status"] = "failed"  # a crashed seed: the two others still give means
    rows = {(r[0], r[1].split(":")[0]): r for r in verdict.rows(short, [])}
    assert rows[("ddf_tuned", "short")][2].startswith(f"no result, not ranked (1 of {len(ddf_bunny)} runs")


def test_the_verdict_gives_a_preset_budgeted_in_epochs_its_own_row_without_a_column_over_shapes():
    import copy

    from ddfbench.report import verdict

    short = compact.read_compact(os.path.join(ROOT, "reports", "default", compact.FILE))
    epochs = []
    for model in ("gan_sdf", "ddf_tuned"):  # ddf_tuned is in the shape suite (here: short): its own row stands
        for r in copy.deepcopy([r for r in short if r["model"] == "ddf_tuned"]):
            r["model"], r["family"] = model, "gan_sdf"
            r["fit"].update(budget="epochs", epochs=40.0007, steps=38982)
            epochs.append(r)
    rows = {(r[0], r[1]): r for r in verdict.rows(short, short, epochs=epochs)}
    row = rows[("gan_sdf", "own: 40 epochs")]
    assert row[2:5] == rows[("ddf_tuned", "short: 3,000 steps")][2:5]  # the same records' accuracy
    assert row[-1] == "–"
    epochs[0]["fit"]["budget"] = "steps"  # one fit bounded otherwise: its steps, not an epoch count
    assert ("gan_sdf", "own: 38,982 steps") in {(r[0], r[1]) for r in verdict.rows(short, short, epochs=epochs)}
    assert not [r for r in rows if r[0] == "ddf_tuned" and r[1].endswith("epochs")]
    assert list(rows)[-1][0] == "gan_sdf"  # the GAN family comes last


def test_the_verdict_footnote_times_one_fixed_build_in_each_record_set_only_at_one_resolution():
    import copy

    from ddfbench.report import verdict

    short = compact.read_compact(os.path.join(ROOT, "reports", "default", compact.FILE))
    built = [r for r in short if r["model"] == "grid_sdf" and r["shape"]["name"] == "bunny"]
    slower = copy.deepcopy(built)
    for r in slower:
        r["cost"]["fit_s"] = 9.5
    elsewhere = copy.deepcopy(built)  # not the work: another shape, a failed run, another model
    elsewhere[0]["shape"]["name"], elsewhere[1]["status"], elsewhere[2]["model"] = "cup", "failed", "mesh"
    for r in elsewhere:
        r["cost"]["fit_s"] = 1000.0
    mean = statistics.mean(r["cost"]["fit_s"] for r in built)
    sets = {"default": short, "shape_suite": slower + elsewhere, "render_time": elsewhere}
    assert verdict.same_work_seconds(sets).endswith(
        f"took {mean:.3g} s in `reports/default`, 9.5 s in `reports/shape_suite`.")
    assert verdict.same_work_seconds({"default": short, "render_time": elsewhere}) == ""  # one set timed it
    for r in slower[:1]:  # one run at another resolution: that set's seconds are not of the same work
        r["cost"]["storage_bytes"] = 2 * r["cost"]["storage_bytes"]
    assert verdict.same_work_seconds({"default": short, "shape_suite": slower}) == ""
    third = copy.deepcopy(built)
    for r in third:
        r["cost"]["fit_s"] = 4.25
    assert verdict.same_work_seconds({"default": short, "shape_suite": slower, "storage": third}).endswith(
        f"took {mean:.3g} s in `reports/default`, 4.25 s in `reports/storage`.")  # the odd set alone is left out


def test_a_preset_whose_every_bunny_run_failed_keeps_its_row_in_the_verdict():
    """Every seed crashed: the row says so, where it vanished from the table (ok_records alone chose the rows)."""
    import copy

    from ddfbench.report import verdict

    short = copy.deepcopy(compact.read_compact(os.path.join(ROOT, "reports", "default", compact.FILE)))
    ddf_bunny = [r for r in short if r["model"] == "ddf_tuned" and r["shape"]["name"] == "bunny"]
    for r in ddf_bunny:
        r["status"] = "failed"
    rows = {(r[0], r[1].split(":")[0]): r for r in verdict.rows(short, [])}
    assert rows[("ddf_tuned", "short")][1] == "short: no run finished"
    assert rows[("ddf_tuned", "short")][2] == f"failed ({len(ddf_bunny)} of {len(ddf_bunny)} runs)"


def test_a_cut_short_records_file_is_one_line_and_leaves_the_generated_files_as_they_were(tmp_path, capsys):
    """regenerate --from-records over reports one of whose records.jsonl.gz is cut short (a crashed copy, a bad
    checkout): one line naming it, exit 2, and index.md, verdict.md and the README, which read it, keep every byte
    (index.md was emptied, then a traceback)."""
    reports = tmp_path / "reports"
    shutil.copytree(os.path.join(ROOT, "reports", "default"), reports / "default")
    for name in ("index.md", "verdict.md"):
        shutil.copy2(os.path.join(ROOT, "reports", name), reports / name)
    readme = tmp_path / "README.md"
    shutil.copy2(os.path.join(ROOT, "README.md"), readme)
    records = reports / "default" / compact.FILE
    records.write_bytes(records.read_bytes()[:3000])
    before = {p: p.read_bytes() for p in (reports / "index.md", reports / "verdict.md", readme)}
    capsys.readouterr()
    assert regenerate_main(["--from-records", "--reports", str(reports), "--readme", str(readme)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"{records}: cannot be read as a compact file" in err
    assert {p: p.read_bytes() for p in before} == before
    assert regenerate_main(["--from-records", "--reports", str(reports), "--readme", str(readme), "--check"]) == 2
    assert "Traceback" not in capsys.readouterr().err



def test_restoring_a_cut_short_or_garbled_compact_file_is_one_line(results, tmp_path, capsys):
    """compact --restore of a file gzip cannot read: one line naming it, exit 2, nothing written (was a traceback)."""
    packed = compact.write_compact(compact.load_records(str(results)), str(tmp_path / "r.jsonl.gz"))
    cut = tmp_path / "cut.jsonl.gz"
    cut.write_bytes(open(packed, "rb").read()[:200])
    garbled = tmp_path / "garbled.jsonl.gz"
    garbled.write_bytes(b"\x15\xab" * 500)
    for path in (cut, garbled):
        assert compact.main(["--restore", str(path), str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"ddfbench.report.compact: {path}: cannot be read as a compact file (")
        assert err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_restore_counts_a_damaged_line_among_those_left_out(results, tmp_path, capsys):
    """A line of the compact file that is not a record is named and counted in the summary (it said 0 left out)."""
    lines = [json.dumps(compact.portable(r)) for r in compact.load_records(str(results)) if r["status"] == "ok"]
    path = tmp_path / "r.jsonl.gz"
    with gzip.open(path, "wt") as fh:
        fh.write("\n".join([lines[0][:-50], *lines[1:]]) + "\n")
    assert compact.main(["--restore", str(path), str(tmp_path / "out")]) == 0
    said = capsys.readouterr()
    assert "line 1: not JSON" in said.err
    assert f"restored {len(lines) - 1} records" in said.out and "1 failed, older, misnamed or damaged" in said.out


def test_compact_into_a_folder_that_cannot_be_written_is_one_line(results, tmp_path, capsys, monkeypatch):
    """compact and compact --restore where the target cannot be written (read-only, full, missing): one line naming
    it, exit 2 (was a traceback); a full disk midway keeps the records restored before it."""
    packed = compact.write_compact(compact.load_records(str(results)), str(tmp_path / "r.jsonl.gz"))
    assert compact.main([str(results), str(tmp_path / "none" / "r.jsonl.gz")]) == 2
    err = capsys.readouterr().err
    assert err == (f"ddfbench.report.compact: {tmp_path / 'none' / 'r.jsonl.gz'}: cannot be written (No such file or "
                   "directory): nothing written\n")
    real, calls = compact.write_json_atomic, []

    def second_fails(path, data):
        calls.append(path)
        if len(calls) == 2:
            raise OSError(errno.ENOSPC, "No space left on device", path)
        real(path, data)

    monkeypatch.setattr(compact, "write_json_atomic", second_fails)
    assert compact.main(["--restore", packed, str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ddfbench.report.compact: {calls[1]}: cannot be written (No space left on device)")
    assert err.count("\n") == 1 and len(compact.load_records(str(tmp_path / "out"))) == 1


def test_a_rebuild_that_fails_midway_leaves_the_committed_report_as_it_was(tmp_path, capsys, monkeypatch):
    """regenerate --from-records where the disk fills after table.md (table.tex cannot be written): one line naming
    the folder, exit 2, and every committed file keeps its bytes (the rebuild wrote into the committed folder itself:
    a new table.md beside the old report.md, an emptied table.tex, then a traceback)."""
    from ddfbench.report import __main__ as report_module

    reports = tmp_path / "reports"
    shutil.copytree(os.path.join(ROOT, "reports", "default"), reports / "default")
    (reports / "default" / "table.md").write_text("hand edit\n")  # so that a rewritten table.md shows
    before = {p.name: p.read_bytes() for p in (reports / "default").iterdir()}

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(report_module, "to_latex", full_disk)
    assert regenerate_main(["--from-records", "--reports", str(reports), "--readme", str(tmp_path / "none.md")]) == 2
    err = capsys.readouterr().err
    assert f"{reports / 'default'}: not rebuilt (OSError: [Errno 28] No space left on device)" in err
    assert "Traceback" not in err
    assert {p.name: p.read_bytes() for p in (reports / "default").iterdir()} == before
    assert [p.name for p in reports.iterdir() if p.name.startswith(".report-")] == []


def test_the_scratch_folder_a_killed_report_left_is_no_report(tmp_path, capsys):
    """A report killed midway leaves its scratch folder (.report-*, with a copy of the records) beside the report
    folder: regenerate --from-records and the index leave it out (they rebuilt it as a report, listed it in index.md
    and failed the check)."""
    reports = tmp_path / "reports"
    shutil.copytree(os.path.join(ROOT, "reports", "default"), reports / "default")
    scratch = reports / ".report-abcd1234"
    scratch.mkdir()
    for name in (compact.FILE, "report_options.json", "report.md"):
        shutil.copy2(reports / "default" / name, scratch)
    assert reports_with_records(str(reports)) == [str(reports / "default")]
    assert index.report_folders(str(reports)) == ["default"]
    assert regenerate_main(["--from-records", "--reports", str(reports), "--readme", str(tmp_path / "none.md")]) == 0
    assert ".report-" not in (reports / "index.md").read_text()
    assert "rebuilt " + str(scratch) not in capsys.readouterr().out
    assert sorted(p.name for p in scratch.iterdir()) == sorted((compact.FILE, "report_options.json", "report.md"))


@pytest.mark.parametrize("text, says", [('{"note": ', "not a readable JSON file (Expecting value"),
                                        ("[1]", "holds a JSON list, not an object"),
                                        ('{"plots": "pareto"}', "plots is a str, not a list or null")])
def test_a_damaged_report_options_file_is_one_line_naming_it(tmp_path, capsys, text, says):
    """report_options.json cut short, not an object or with a wrong type: one line naming it, exit 2, the report
    folder as it was (was a traceback)."""
    reports = tmp_path / "reports"
    shutil.copytree(os.path.join(ROOT, "reports", "default"), reports / "default")
    (reports / "default" / "report_options.json").write_text(text)
    before = {p.name: p.read_bytes() for p in (reports / "default").iterdir()}
    assert regenerate_main(["--from-records", "--reports", str(reports), "--readme", str(tmp_path / "none.md")]) == 2
    err = capsys.readouterr().err
    assert f"ddfbench.report.regenerate: {reports / 'default' / 'report_options.json'}: {says}" in err
    assert "Traceback" not in err
    assert {p.name: p.read_bytes() for p in (reports / "default").iterdir()} == before
