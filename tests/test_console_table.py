"""The terminal's table: the few columns a first look needs, in lines a terminal of 100 columns shows."""

import os

from ddfbench.report.compact import read_compact
from ddfbench.report.tables import console_table, summarize

DEFAULT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "reports", "default",
                       "records.jsonl.gz")


def test_the_default_runs_table_fits_100_columns_with_a_row_per_model():
    records = read_compact(DEFAULT)
    lines = console_table(summarize(records)).splitlines()
    assert max(len(line) for line in lines) <= 100
    assert lines[0].split() == ["model", "shape", "n", "CD-L2", "×10³", "F@0.01", "fit", "s", "frame", "s", "bytes"]
    assert sorted(line.split()[0] for line in lines[1:]) == sorted({r["model"] for r in records})


def test_one_run_shows_its_values_without_a_spread():
    (rec,) = [r for r in read_compact(DEFAULT) if r["model"] == "ddf_tuned" and r["config"]["seed"] == 0]
    row = console_table(summarize([rec])).splitlines()[1].split()
    assert row[:3] == ["ddf_tuned", "bunny", "1"] and "±" not in " ".join(row)
    assert float(row[3]) == float(f"{rec['metrics']['chamfer_l2'] * 1e3:.3g}")


def test_a_sweep_s_rows_show_the_settings_that_tell_them_apart():
    """The ablation's seven rows are all `ddf bone`: the terminal shows the sampling levels each ran."""
    records = read_compact(DEFAULT.replace("default", "ablation"))
    lines = console_table(summarize(records)).splitlines()
    assert lines[0].split()[:4] == ["model", "shape", "sampling", "n"]  # the sweep's axis: sampling={s_fc:..}
    rows = {line.split()[2] for line in lines[1:]}
    assert len(rows) == len(lines) - 1 == 7 and "{s_fc:30,s_dr:10,s_p:10}" in rows
