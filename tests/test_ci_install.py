"""CI installs pinned versions (.ci/constraints.txt): every dependency of pyproject.toml and of each extra is pinned
there, so a dependency added to pyproject.toml without a pin fails here instead of floating in CI."""

import os
import re

import pytest

tomllib = pytest.importorskip("tomllib")  # Python 3.11+ (CI's)
Requirement = pytest.importorskip("packaging.requirements").Requirement

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def requirement_name(spec: str) -> str:
    """The distribution a requirement names: 'ray[default]>=2.40,<3' -> 'ray'."""
    return canonical(re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", spec).group(1))


def test_every_dependency_and_extra_is_pinned_for_ci():
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as fh:
        project = tomllib.load(fh)["project"]
    wanted = [spec for spec in project["dependencies"] if "platform_machine != 'x86_64'" not in spec]
    wanted += [spec for extra in project["optional-dependencies"].values() for spec in extra]
    with open(os.path.join(ROOT, ".ci", "constraints.txt")) as fh:
        pinned = dict(line.strip().split("==", 1) for line in fh if "==" in line and not line.startswith("#"))
    pinned = {canonical(name): version for name, version in pinned.items()}
    missing = sorted({requirement_name(spec) for spec in wanted} - set(pinned))
    assert not missing, f".ci/constraints.txt pins no version of {missing}"
    for spec in map(Requirement, wanted):  # and each pin satisfies pyproject.toml's range
        version = pinned[canonical(spec.name)]
        assert spec.specifier.contains(version, prereleases=True), (str(spec), version)
    assert pinned["torch"].startswith("2.13.0")  # the machine's CPU build, installed by pip before the rest
    with open(os.path.join(ROOT, ".ci", "run")) as fh:
        assert "-c .ci/constraints.txt" in fh.read()


@pytest.mark.slow
def test_the_wheel_carries_every_config_so_an_install_runs_from_any_folder(tmp_path):
    """`pip install .` builds a wheel: ddfbench/conf (in a checkout a link to conf/) must arrive as files."""
    import shutil
    import subprocess
    import sys
    import zipfile

    source = tmp_path / "source"  # a copy of what the build reads: it leaves build/ in the tree it builds
    shutil.copytree(os.path.join(ROOT, "ddfbench"), source / "ddfbench", symlinks=True,
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(os.path.join(ROOT, "conf"), source / "conf")
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(os.path.join(ROOT, name), source)
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                            "-w", str(tmp_path / "dist"), str(source)], capture_output=True, text=True, timeout=300)
    assert built.returncode == 0, built.stderr[-2000:]
    (wheel,) = (tmp_path / "dist").glob("ddfbench-*.whl")
    carried = {name for name in zipfile.ZipFile(wheel).namelist() if name.startswith("ddfbench/conf/")}
    conf = os.path.join(ROOT, "conf")
    wanted = {f"ddfbench/conf/{os.path.relpath(os.path.join(d, f), conf)}" for d, _, files in os.walk(conf)
              for f in files if f.endswith(".yaml")}
    assert len(wanted) > 50 and carried == wanted
    assert os.path.realpath(os.path.join(ROOT, "ddfbench", "conf")) == os.path.realpath(conf)
