"""A re-measurement's tables regenerate from the rows it measured (ddfbench.report.measured): the rows come back as
written (NaN and order kept), `regenerate --from-records --check` rebuilds the folder measuring nothing and catches a
hand-edited table, the index counts it as regenerating, and a folder naming an unknown tool is a one-line error."""

import gzip
import json
import math
import os

import pytest

from ddfbench.core.errors import InputError
from ddfbench.report import index, measured
from ddfbench.report.edge_error import BANDS, COLUMNS
from ddfbench.report.regenerate import main as regenerate_main
from tests.conftest import rebuilt_differences

HEAD = {"tool": "edge_error", "command": "`python -m ddfbench.report.edge_error <out_dir>/pareto --out x`",
        "what": "2 runs' saved renders (0 unreadable), edges at depth steps > 0.1",
        "provenance": "records of code abcdef0, measured by code 1234567"}


def edge_rows():
    """Two runs of one configuration, a row per band each, as edge_error measures them; run 1 has no far pixel."""
    rows = []
    for seed, value in ((0, 0.25), (1, 0.75)):
        run = {"model": "ddf_tuned", "shape": "bunny", "capacity": "c2", "seed": seed, "key": f"{seed:016x}",
               "no_result": False, **{key: value for key, _, _ in COLUMNS}}
        if seed == 1:
            run["depth_mae_far"] = math.nan
        rows += [{**run, "band": name, "pixels": 10.0, "mask_errors": 1.0, "both": 9.0, "abs_depth": 0.5}
                 for name, _ in BANDS]
    return rows


def test_the_rows_come_back_as_written_and_the_tables_are_written_from_them(tmp_path):
    rows = edge_rows()
    md = measured.write(str(tmp_path / "m"), HEAD, rows)
    head, back = measured.read(str(tmp_path / "m"))
    assert head == HEAD and [list(r) for r in back] == [list(r) for r in rows]  # the columns' order is kept
    assert math.isnan(back[4]["depth_mae_far"]) and back[0]["depth_mae_far"] == 0.25 and back[0]["seed"] == 0
    assert md == (tmp_path / "m" / "table.md").read_text()
    assert md.startswith(f"{HEAD['command']}: {HEAD['what']}, {HEAD['provenance']}.\n\n| model |")
    table = md.splitlines()[4]  # the pooled row: two runs, one defines the far figure
    assert table.startswith("| ddf_tuned | bunny | c2 | 2 | 50 ± 35") and "(n = 1)" in table
    assert rebuilt_differences(tmp_path / "m", tmp_path / "again") == []
    with gzip.open(tmp_path / "m" / measured.FILE, "rb") as fh:  # deterministic: one set of rows, one file
        first = fh.read()
    measured.write(str(tmp_path / "m2"), HEAD, rows)
    assert (tmp_path / "m" / measured.FILE).read_bytes() == (tmp_path / "m2" / measured.FILE).read_bytes()
    assert first.count(b"\n") == len(rows)


def test_the_header_writes_the_records_folder_without_the_machines_path(tmp_path):
    results = str(tmp_path / "res" / "pareto")
    head = measured.header("edge_error", [results, "--out", "reports/x"], "what", [], results)
    assert head["command"] == "`python -m ddfbench.report.edge_error <out_dir>/pareto --out reports/x`"
    assert str(tmp_path) not in json.dumps(head)


def test_regenerate_rebuilds_a_remeasurement_and_fails_on_a_hand_edited_table(tmp_path, capsys):
    folder = tmp_path / "pareto" / "edge_error"
    measured.write(str(folder), HEAD, edge_rows())
    readme = str(tmp_path / "none.md")
    assert regenerate_main(["--from-records", "--reports", str(tmp_path), "--readme", readme]) == 0
    assert index.provenance(str(folder)) == index.Provenance(2, ["abcdef0"], index.FROM_ROWS)
    text = (tmp_path / index.FILE).read_text()
    assert "1 of 1 report folders regenerate from committed files: 0 reports from their records" in text
    assert "1 re-measurements of runs' artifacts (meshes, networks, renders) from the rows they measured" in text
    assert f"| {index.FROM_ROWS} |" in text
    assert regenerate_main(["--from-records", "--check", "--reports", str(tmp_path), "--readme", readme]) == 0
    assert "1 re-measurement(s) with their measured rows and 0 tuning studies with their trial tables: 0 file(s) differ" \
        in capsys.readouterr().out
    md = folder / "table.md"
    md.write_text(md.read_text().replace("| 2 | 50", "| 2 | 51"))
    assert regenerate_main(["--from-records", "--check", "--reports", str(tmp_path), "--readme", readme]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err == [f"ddfbench.report.regenerate: {md} differs from its rebuild from its records"]
    assert regenerate_main(["--from-records", "--reports", str(tmp_path), "--readme", readme]) == 0
    assert "| 2 | 50" in md.read_text()  # rebuilt in place from the rows


def test_a_stale_table_the_rebuild_does_not_write_is_a_difference_but_the_folders_readme_is_not(tmp_path, capsys):
    folder = tmp_path / "r"
    measured.write(str(folder), HEAD, edge_rows())
    (folder / "README.md").write_text("what these rows are, written by hand\n")
    (folder / "paired.md").write_text("left by an earlier --store-as run into this folder\n")
    readme = str(tmp_path / "none.md")
    assert regenerate_main(["--from-records", "--check", "--reports", str(tmp_path), "--readme", readme]) == 1
    assert capsys.readouterr().err.splitlines() == [
        f"ddfbench.report.regenerate: {folder / 'paired.md'} differs from its rebuild from its records"]
    assert rebuilt_differences(folder, tmp_path / "again") == ["paired.md"]


@pytest.mark.parametrize("meta, rows, says", [
    (json.dumps({**HEAD, "tool": "os"}), None, r"measured\.json: tool 'os' is not one of"),
    (json.dumps({"tool": "zero_level"}), None, r"measured\.json: needs a JSON object with tool \(a str\), command \(a str\)"),
    ("[]", None, r"measured\.json: needs a JSON object"),
    ('{"tool": ', None, r"measured\.json: not a readable JSON file"),
    (None, b"not gzip", r"measured\.jsonl\.gz: not measured rows"),
    (None, gzip.compress(b'{"model": "a"}\n[1]\n', mtime=0),
     r"measured\.jsonl\.gz: not measured rows \(line 2 is a JSON list"),
], ids=["unknown tool", "missing keys", "not an object", "not JSON", "not gzip", "a row not an object"])
def test_a_bad_measured_file_is_one_line_naming_it_and_regenerate_exits_2(tmp_path, capsys, meta, rows, says):
    folder = tmp_path / "r"
    measured.write(str(folder), HEAD, edge_rows())
    if meta is not None:
        (folder / measured.META).write_text(meta)
    if rows is not None:
        (folder / measured.FILE).write_bytes(rows)
    with pytest.raises(InputError, match=says):
        measured.rebuild(str(folder), str(tmp_path / "x"))
    capsys.readouterr()
    assert regenerate_main(["--from-records", "--check", "--reports", str(tmp_path),
                            "--readme", str(tmp_path / "none.md")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"ddfbench.report.regenerate: {folder}{os.sep}measured.json")


def test_numpy_scalars_are_written_as_numbers_and_other_objects_refused_leaving_no_file(tmp_path):
    import numpy as np

    rows = [{**row, "pixels": np.float32(10.0), "seed": np.int64(row["seed"]), "no_result": np.bool_(False)}
            for row in edge_rows()]
    measured.write(str(tmp_path / "m"), HEAD, rows)
    back = measured.read(str(tmp_path / "m"))[1]
    assert json.dumps(back) == json.dumps([{**row, "pixels": 10.0} for row in edge_rows()])  # NaN != NaN: as text
    assert type(back[0]["seed"]) is int and back[0]["no_result"] is False
    with pytest.raises(TypeError, match="object is not a measured value"):
        measured.write(str(tmp_path / "bad"), HEAD, [{**edge_rows()[0], "pixels": object()}])
    assert not os.listdir(tmp_path / "bad")  # no half-written rows


def test_part_of_a_measurement_does_not_replace_a_whole_one(tmp_path, capsys):
    """With an unreadable run, a folder that holds a measurement keeps it (one line); a new folder gets the rows
    measured (exit 1 either way)."""
    folder = tmp_path / "m"
    measured.write(str(folder), HEAD, edge_rows())
    before = {p.name: p.read_bytes() for p in folder.iterdir()}
    assert measured.publish("edge_error", str(folder), HEAD, edge_rows()[:2], failed=1) == 1
    assert "1 run(s) unreadable" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == before
    assert measured.publish("edge_error", str(tmp_path / "new"), HEAD, edge_rows()[:2], failed=1) == 1
    assert (tmp_path / "new" / measured.FILE).is_file()
    assert measured.publish("edge_error", str(folder), HEAD, edge_rows(), failed=0) == 0  # a whole one replaces
