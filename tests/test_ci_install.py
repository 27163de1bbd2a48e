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
