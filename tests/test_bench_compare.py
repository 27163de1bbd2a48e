"""`python -m ddfbench.bench.compare`: rows matched across bench JSON files by section and measure, the
noise and change computed from their ratios, and the verdict flipping when the ranges stop overlapping."""

import json

import pytest

from ddfbench.bench.compare import Shift, main, shifts


def bench_json(path, ratios: dict[tuple[str, str], float]):
    """A bench JSON file (the fields compare reads) with one row per (section, measure)."""
    sections: dict = {}
    for (section, measure), ratio in ratios.items():
        sections.setdefault(section, {"rows": []})["rows"].append({"measure": measure, "ratio": ratio})
    path.write_text(json.dumps({"sections": sections}))
    return str(path)


def test_rows_match_by_section_and_measure_and_missing_rows_are_named(tmp_path):
    b1 = bench_json(tmp_path / "b1.json", {("oracle", "embree"): 0.20, ("ddf", "intersect"): 0.10})
    b2 = bench_json(tmp_path / "b2.json", {("oracle", "embree"): 0.24, ("ddf", "intersect"): 0.12})
    a1 = bench_json(tmp_path / "a1.json", {("oracle", "embree"): 0.22})
    a2 = bench_json(tmp_path / "a2.json", {("oracle", "embree"): 0.30, ("grid", "build"): 2.0})
    rows, missing = shifts([b1, b2], [a1, a2])
    assert [(r.section, r.measure) for r in rows] == [("oracle", "embree")]
    assert missing == ["ddf: intersect", "grid: build"]
    (row,) = rows
    assert row.before == [0.20, 0.24] and row.after == [0.22, 0.30]
    assert row.change == pytest.approx(0.26 / 0.22 - 1)
    assert Shift.spread(row.before) == pytest.approx(0.04 / 0.22)
    assert row.within_noise  # the mean moved 0.04, the after runs' range is 0.08


@pytest.mark.parametrize("after, within", [
    ((0.255, 0.255), True),  # moved 0.035 < the before range 0.04
    ((0.265, 0.265), False),  # moved 0.045 > 0.04, and the after runs agree
    ((0.24, 0.31), True),    # moved 0.055, but the after runs alone differ by 0.07
    ((0.16, 0.17), False),   # moved -0.055
    ((0.22, 0.22), True)])
def test_within_noise_compares_the_change_of_the_mean_with_the_larger_range(after, within):
    assert Shift("s", "m", [0.20, 0.24], list(after)).within_noise is within


def test_cli_writes_the_table_and_refuses_a_file_that_is_not_a_bench_run(tmp_path, capsys):
    b = [bench_json(tmp_path / f"b{i}.json", {("metrics", "chamfer"): r}) for i, r in enumerate((1.0, 1.1))]
    a = [bench_json(tmp_path / f"a{i}.json", {("metrics", "chamfer"): r}) for i, r in enumerate((1.5, 1.6))]
    out = tmp_path / "cmp.md"
    assert main(["--before", *b, "--after", *a, "--out", str(out)]) == 0
    text = out.read_text()
    assert "0 of 1 rows within noise" in text and "| metrics | chamfer | 1, 1.1 | 1.5, 1.6 |" in text
    bad = tmp_path / "bad.json"
    bad.write_text('{"rows": []}')
    capsys.readouterr()
    assert main(["--before", str(bad), *b, "--after", *a]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.json: not a ddfbench.bench JSON file" in err[0]
