"""`python -m ddfbench.bench.compare`: rows matched across bench JSON files by section and measure, the
change of the mean judged against the larger run-to-run range of either code (on the ratio and on the
row's own figure), and refusals of what cannot be compared."""

import json

import pytest

from ddfbench.bench.compare import change, main, shifts, within_noise


def bench_json(path, rows: dict[tuple[str, str], tuple[float, float]], threads=2):
    """A bench JSON file (the fields compare reads): {(section, measure): (ratio, value)}."""
    sections: dict = {}
    for (section, measure), (ratio, value) in rows.items():
        sections.setdefault(section, {"rows": []})["rows"].append(
            {"measure": measure, "ratio": ratio, "value": value, "unit": "rays/s"})
    doc = {"options": {"device": "cpu", "sizes": "default"}, "env": {"threads": threads}, "sections": sections}
    path.write_text(json.dumps(doc))
    return str(path)


def test_rows_match_by_section_and_measure_and_missing_rows_are_named(tmp_path):
    b1 = bench_json(tmp_path / "b1.json", {("oracle", "embree"): (0.20, 10.0), ("ddf", "intersect"): (0.1, 1.0)})
    b2 = bench_json(tmp_path / "b2.json", {("oracle", "embree"): (0.24, 11.0), ("ddf", "intersect"): (0.1, 1.0)})
    a1 = bench_json(tmp_path / "a1.json", {("oracle", "embree"): (0.22, 10.0)})
    a2 = bench_json(tmp_path / "a2.json", {("oracle", "embree"): (0.30, 10.5), ("grid", "build"): (2.0, 1.0)})
    rows, missing = shifts([b1, b2], [a1, a2])
    assert [(r.section, r.measure) for r in rows] == [("oracle", "embree")]
    assert missing == ["ddf: intersect", "grid: build"]
    (row,) = rows
    assert (row.ratio_before, row.ratio_after, row.value_before, row.value_after) == (
        [0.20, 0.24], [0.22, 0.30], [10.0, 11.0], [10.0, 10.5])
    assert change(row.ratio_before, row.ratio_after) == pytest.approx(0.26 / 0.22 - 1)


@pytest.mark.parametrize("after, within", [
    ((0.255, 0.255), True),   # moved 0.035 < the before range 0.04
    ((0.265, 0.265), False),  # moved 0.045 > 0.04, and the after runs agree
    ((0.24, 0.31), True),     # moved 0.055, but the after runs alone differ by 0.07
    ((0.16, 0.17), False),    # moved -0.055
    ((0.22, 0.22), True)])
def test_within_noise_compares_the_change_of_the_mean_with_the_larger_range(after, within):
    assert within_noise([0.20, 0.24], list(after)) is within


def test_change_of_a_zero_mean_is_nan_not_an_error():
    assert change([0.0, 0.0], [1.0, 1.0]) != change([0.0, 0.0], [1.0, 1.0])  # NaN


def test_cli_table_judges_ratio_and_figure_and_refuses_what_cannot_be_compared(tmp_path, capsys):
    # the ratio moved out of its noise while the figure itself stayed: the reference moved
    b = [bench_json(tmp_path / f"b{i}.json", {("metrics", "chamfer"): (r, 4.0 + i * 0.1)}) for i, r in enumerate((1.0, 1.1))]
    a = [bench_json(tmp_path / f"a{i}.json", {("metrics", "chamfer"): (r, 4.05)}) for i, r in enumerate((1.5, 1.6))]
    out = tmp_path / "cmp.md"
    assert main(["--before", *b, "--after", *a, "--out", str(out)]) == 0
    text = out.read_text()
    assert "0 of 1 rows within noise by their ratio; 1 more by their own figure" in text
    assert "| metrics | chamfer | 1, 1.1 | 1.5, 1.6 |" in text and "| +48% | **no** |" in text and "| yes |" in text
    capsys.readouterr()
    bad = tmp_path / "bad.json"
    bad.write_text('{"rows": []}')
    other_threads = bench_json(tmp_path / "t1.json", {("metrics", "chamfer"): (1.0, 4.0)}, threads=1)
    for argv, why in (([str(bad), *b[1:]], "bad.json: not a ddfbench.bench JSON file"),
                      ([b[0]], "need two runs of each code"),
                      ([b[0], other_threads], "the files differ in device/sizes/threads")):
        assert main(["--before", *argv, "--after", *a]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and why in err[0], err
