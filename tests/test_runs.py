"""Record keys, atomic writes and resume decisions."""

import json
import os

import pytest

from ddfbench.run import runs


def base_cfg():
    return {"shape": {"name": "bunny"}, "model": {"family": "mesh", "faces": 0}, "seed": 0,
            "out_dir": "results", "force": False, "threads": 2, "experiment_name": "x"}


def test_key_ignores_non_semantic_keys_and_tracks_semantic_ones():
    a, b = base_cfg(), base_cfg()
    b.update(out_dir="/elsewhere", force=True, threads=7, experiment_name="y", quiet=True)
    assert runs.config_key(a) == runs.config_key(b)
    c = base_cfg()
    c["model"]["faces"] = 2000
    assert runs.config_key(a) != runs.config_key(c)
    d = base_cfg()
    d["seed"] = 1
    assert runs.config_key(a) != runs.config_key(d)


def test_key_is_independent_of_dict_order():
    a = base_cfg()
    b = dict(reversed(list(a.items())))
    assert runs.config_key(a) == runs.config_key(b)


def test_atomic_write_leaves_no_temporary_and_is_strict_json(tmp_path):
    path = tmp_path / "a" / "record.json"
    runs.write_json_atomic(str(path), {"status": "ok", "x": float("inf"), "y": [1.0, float("nan")]})
    assert os.listdir(path.parent) == ["record.json"]
    data = json.loads(path.read_text())  # strict: would fail on bare Infinity/NaN? json accepts them, so check text
    assert "Infinity" not in path.read_text() and data["x"] == "inf" and data["y"][1] == "nan"


def record(status: str, **fields) -> dict:
    """The least a record holds to be read as one (runs.record_problem), with `fields` on top."""
    return {"status": status, "schema_version": runs.SCHEMA_VERSION, "key": "k", "experiment": "e", "metrics": {},
            "cost": {}, "config": {}, "shape": {}, **fields}


def test_failed_write_keeps_the_old_record(tmp_path):
    path = str(tmp_path / "record.json")
    runs.write_json_atomic(path, record("ok", schema_version=runs.SCHEMA_VERSION))

    class Unserializable:
        pass

    try:
        runs.write_json_atomic(path, {"status": "failed", "bad": Unserializable()})
    except TypeError:
        pass
    assert runs.read_record(path)["status"] == "ok"
    assert os.listdir(tmp_path) == ["record.json"]


def test_is_done_only_for_ok_records_of_this_schema(tmp_path):
    path = str(tmp_path / "record.json")
    assert not runs.is_done(path)
    runs.write_json_atomic(path, record("failed", schema_version=runs.SCHEMA_VERSION))
    assert not runs.is_done(path)
    runs.write_json_atomic(path, record("ok", schema_version=runs.SCHEMA_VERSION - 1))
    assert not runs.is_done(path)
    runs.write_json_atomic(path, record("ok", schema_version=runs.SCHEMA_VERSION))
    assert runs.is_done(path)
    with open(path, "w") as fh:
        fh.write("{ not json")
    assert not runs.is_done(path)


def test_environment_records_optional_package_versions_whatever_was_imported(monkeypatch):
    """open3d, warp, pymeshlab and embreex versions come from the installed distributions (pymeshlab has no
    __version__, open3d installs as open3d-cpu); a blocked import (a machine without it) records None."""
    import sys

    from ddfbench.run.runs import OPTIONAL, environment
    from ddfbench.truth.shapes import load_shape

    load_shape({"name": "bone"})  # imports pymeshlab, whose module has no __version__
    versions = environment("cpu", 1)["versions"]
    assert set(OPTIONAL) <= set(versions) and versions["pymeshlab"] and versions["open3d"]
    monkeypatch.setitem(sys.modules, "open3d", None)
    assert environment("cpu", 1)["versions"]["open3d"] is None


def test_environment_names_the_cpu_model_and_ddfbench_s_version(tmp_path):
    import ddfbench

    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 9B14 96-Core Processor\n"
                    "processor\t: 1\nmodel name\t: AMD EPYC 9B14 96-Core Processor\n")
    assert runs.cpu_model(str(info)) == "AMD EPYC 9B14 96-Core Processor"
    assert runs.cpu_model(str(tmp_path / "none")) is None and runs.cpu_model(os.devnull) is None
    assert runs.environment("cpu", 1)["versions"]["ddfbench"] == ddfbench.__version__


def test_a_copied_tree_names_its_commit_through_the_environment(monkeypatch):
    """A lent GPU machine gets the working tree over a stale .git (or none): $DDFBENCH_GIT_SHA names the commit."""
    from ddfbench.run import runs

    monkeypatch.setattr(runs, "_git", lambda *args: "stale")
    monkeypatch.delenv(runs.GIT_SHA_ENV, raising=False)
    env = runs.environment("cpu", 1)
    assert env["git_sha"] == "stale" == runs.code_sha() and env["git_sha_from"] == "git"
    monkeypatch.setenv(runs.GIT_SHA_ENV, "0123abc")
    env = runs.environment("cpu", 1)
    assert env["git_sha"] == env["code_sha"] == "0123abc" and env["git_sha_from"] == "DDFBENCH_GIT_SHA"


def test_find_records_names_each_file_that_is_not_a_record(tmp_path, capsys):
    runs.write_json_atomic(str(tmp_path / "good" / "record.json"), record("ok", key="good"))
    bad = {"truncated": b'{"key": "t", "stat', "latin1": b'{"key": "\xff"}', "list": b"[1, 2]",
           "fields": b'{"status": "ok", "key": "f"}'}
    for name, content in bad.items():
        (tmp_path / name).mkdir()
        (tmp_path / name / "record.json").write_bytes(content)
    assert [r["key"] for r in runs.find_records(str(tmp_path))] == ["good"]
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 4
    for name, why in (("truncated", "JSONDecodeError"), ("latin1", "UnicodeDecodeError"), ("list", "JSON list"),
                      ("fields", "not a run record: field 'experiment' is missing")):
        (line,) = [ln for ln in lines if str(tmp_path / name / "record.json") in ln]
        assert why in line
    assert runs.read_record(str(tmp_path / "list" / "record.json")) is None  # a rerun writes it anew


def test_find_records_keeps_one_record_a_key_and_leaves_out_another_schema(tmp_path, capsys):
    """A copied run folder is not a second seed, and a record the sweep would rerun is not counted as done."""
    for folder in ("a", "copy_of_a"):
        runs.write_json_atomic(str(tmp_path / folder / "record.json"), record("ok", key="k"))
    runs.write_json_atomic(str(tmp_path / "old" / "record.json"),
                           record("ok", key="o", schema_version=runs.SCHEMA_VERSION - 1))
    unversioned = {k: v for k, v in record("ok", key="u").items() if k != "schema_version"}  # made by hand
    runs.write_json_atomic(str(tmp_path / "hand" / "record.json"), unversioned)
    assert [r["_dir"] for r in runs.find_records(str(tmp_path))] == [str(tmp_path / "a")]
    assert not runs.is_done(str(tmp_path / "hand" / "record.json"))  # what a report counts, a sweep does not rerun
    err = capsys.readouterr().err
    assert f"skipped {tmp_path / 'copy_of_a' / 'record.json'}: a second record of run " in err
    assert f"(the first: {tmp_path / 'a' / 'record.json'})" in err
    assert (f"skipped {tmp_path / 'old' / 'record.json'}: schema_version {runs.SCHEMA_VERSION - 1}, not "
            f"{runs.SCHEMA_VERSION} (a sweep runs it again)") in err
    assert (f"skipped {tmp_path / 'hand' / 'record.json'}: no schema_version, not {runs.SCHEMA_VERSION} (a sweep "
            "runs it again)") in err


def test_a_writer_that_fails_midway_leaves_the_old_file_and_no_temporary(tmp_path):
    from ddfbench.core.atomic import write_atomic

    path = tmp_path / "data.bin"
    path.write_bytes(b"old")

    def half(fh):
        fh.write(b"new, cut")
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left"):
        write_atomic(str(path), half, "wb")
    assert path.read_bytes() == b"old" and os.listdir(tmp_path) == ["data.bin"]
    assert write_atomic(str(path), lambda fh: fh.write(b"new"), "wb") == str(path) and path.read_bytes() == b"new"
    mask = os.umask(0)
    os.umask(mask)
    assert oct(os.stat(path).st_mode & 0o777) == oct(0o666 & ~mask)  # not mkstemp's 0600


def test_an_interrupt_midway_leaves_the_old_file_and_no_temporary(tmp_path):
    """Ctrl-C (KeyboardInterrupt, not an Exception) inside the writer still removes the temporary file. Kills
    catching Exception for BaseException in atomic._publish."""
    from ddfbench.core.atomic import write_atomic

    path = tmp_path / "record.json"
    path.write_text("old")

    def interrupted(fh):
        fh.write("new, cut")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_atomic(str(path), interrupted)
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["record.json"]


def test_leftovers_finds_the_temporary_of_a_name_with_glob_characters(tmp_path):
    """A file name holding [ ] or * (a shape file name, a key) still finds its own killed write's temporary, and
    only its own. Kills leftovers dropping glob.escape of the name."""
    from ddfbench.core.atomic import leftovers

    path = tmp_path / "bunny[1].json"
    mine, other = tmp_path / ".bunny[1].json.abc123.tmp", tmp_path / ".bunny1.json.abc123.tmp"
    mine.write_text("cut")
    other.write_text("cut")
    assert leftovers(str(path)) == [str(mine)]


def test_a_filesystem_that_refuses_modes_still_gets_the_file_and_a_killed_write_s_temporary_is_found(tmp_path,
                                                                                                     monkeypatch):
    from ddfbench.core import atomic
    from ddfbench.fit.checkpoint import Checkpoint

    def refuse(fd, mode):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(atomic.os, "fchmod", refuse)
    path = tmp_path / "fit_checkpoint.pt"
    atomic.write_atomic(str(path), lambda fh: fh.write(b"state"), "wb")
    assert path.read_bytes() == b"state" and os.listdir(tmp_path) == ["fit_checkpoint.pt"]
    killed = tmp_path / ".fit_checkpoint.pt.x1y2z3.tmp"  # what a save killed mid-write leaves
    killed.write_bytes(b"half")
    assert atomic.leftovers(str(path)) == [str(killed)]
    Checkpoint(str(path)).remove()
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("family", ["ddf", "neural_sdf", "gan_sdf", "grid_sdf", "mesh"])
def test_a_model_save_that_cannot_reach_the_disk_keeps_the_old_artifact_and_leaves_no_temporary(family, tmp_path,
                                                                                                monkeypatch):
    import numpy as np
    import trimesh

    from ddfbench.core import atomic
    from ddfbench.models import available_families, load_family

    if family not in available_families():
        pytest.skip(f"no {family} family in this checkout")
    rep = load_family(family)({"resolution": 4} if family == "grid_sdf" else {"faces": 0} if family == "mesh" else {},
                              0.7)
    if family == "grid_sdf":
        rep._set_grid(np.zeros((4, 4, 4), np.float32))
    if family == "mesh":
        rep.mesh = trimesh.creation.box()
    path = rep.save(str(tmp_path / "model"))
    old = open(path, "rb").read()

    def full(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic.os, "fsync", full)  # every artifact is synced before it replaces the old one
    if family == "grid_sdf":
        rep._set_grid(np.ones((4, 4, 4), np.float32))
    with pytest.raises(OSError, match="No space left"):
        rep.save(str(tmp_path / "model"))
    assert open(path, "rb").read() == old and os.listdir(tmp_path) == [os.path.basename(path)]
