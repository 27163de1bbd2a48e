"""tools/device/: the shell scripts of the lent-GPU calls parse, and their paths hold from where each one runs
(make_dev_folders.sh from tools/device/, the others copied into .devA/ or .devB/ at the repository root)."""

import os
import re
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TOOLS = os.path.join(ROOT, "tools", "device")
SCRIPTS = sorted(f for f in os.listdir(TOOLS) if f.endswith(".sh"))
MAKER = "make_dev_folders.sh"


def text(name: str) -> str:
    with open(os.path.join(TOOLS, name)) as fh:
        return fh.read()


def copies() -> dict[str, str]:
    """script -> the staging folder (.devA or .devB) make_dev_folders.sh copies it into."""
    out = {}
    for src, dst in re.findall(r"cp ((?:\$here/\S+ ?)+) (\.dev[AB])/", text(MAKER)):
        for name in src.split():
            out[name.removeprefix("$here/")] = dst
    return out


def cd_target(name: str, runs_in: str) -> str:
    """The folder the script's `cd "$(dirname "$0")/REL"` reaches when the script lies in runs_in."""
    rel = re.search(r'^cd "\$\(dirname "\$0"\)/([./]+)"', text(name), re.M).group(1)
    return os.path.normpath(os.path.join(runs_in, rel))


@pytest.mark.parametrize("name", SCRIPTS)
def test_a_script_parses(name):
    assert subprocess.run(["bash", "-n", os.path.join(TOOLS, name)]).returncode == 0


def test_the_maker_copies_every_script_that_exists_and_runs_from_the_root():
    assert cd_target(MAKER, TOOLS) == ROOT
    here = re.search(r"^here=(\S+)$", text(MAKER), re.M).group(1)
    assert os.path.join(ROOT, here) == TOOLS
    assert set(copies()) == set(SCRIPTS) - {MAKER}


def sourced() -> set[tuple[str, str]]:
    """(script, staging folder) of each `source .devB/setup_b.sh` in the scripts: a sourced one runs in its caller's
    folder, so it needs no cd of its own."""
    found = (re.findall(r"source (\.dev[AB])/(\S+\.sh)", text(other)) for other in SCRIPTS)
    return {(name, folder) for pairs in found for folder, name in pairs}


SOURCED = {name for name, _ in sourced()}


def test_a_copied_script_without_a_cd_of_its_own_is_sourced_from_where_it_is_staged():
    no_cd = {name for name in set(SCRIPTS) - {MAKER} if not re.search(r'^cd "\$\(dirname "\$0"\)/', text(name), re.M)}
    assert no_cd == SOURCED
    assert all(copies()[name] == folder for name, folder in sourced()), sourced()


@pytest.mark.parametrize("name", sorted(set(SCRIPTS) - {MAKER} - SOURCED))
def test_a_copied_script_reaches_the_root_from_its_staging_folder(name):
    staged_in = os.path.join(ROOT, copies()[name])
    assert cd_target(name, staged_in) == ROOT


def test_the_training_call_brings_its_run_folders_back_as_one_file():
    script = text("run_train_curves.sh")
    assert "out_dir=$OUT/res" in script
    assert re.search(r"tar -C \$OUT -czf \$OUT/res\.tgz .*res && rm -rf \$OUT/res", script)
