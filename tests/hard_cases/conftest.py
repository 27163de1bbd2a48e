"""Fixtures of the hard-case suite: `hard/...` shapes as normalized Shapes, oracles, ray helpers."""

import importlib.util

import numpy as np
import pytest
import torch

from ddfbench.core import plugins
from ddfbench.models import available_families
from ddfbench.truth.oracle import full_backend
from ddfbench.truth.shapes import HARD_CASES, Shape, load_shape

torch.set_num_threads(1)


def hard_shape(name: str, **params) -> Shape:
    """A `hard/...` catalog shape, validated and normalized exactly as shapes.load_shape does for any mesh."""
    assert name in HARD_CASES, name
    return load_shape({"name": name, "params": params})


def unit(v: np.ndarray) -> np.ndarray:
    """Rows of v (N,3) scaled to unit length."""
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def has_family(name: str) -> bool:
    return name in available_families()


def has_warp() -> bool:
    """Whether NVIDIA Warp (the `gpu` extra) imports; CI installs it, so the warp cases run there."""
    return importlib.util.find_spec("warp") is not None


# the ground truth where open3d is missing (a GPU machine that gets only small wheels): Warp answers every query
ORACLE_BACKEND = full_backend()


def backend_params(*names: str) -> list:
    """pytest params of ray-cast backend names; a name with "warp" in it is skipped where Warp is missing."""
    skip = pytest.mark.skipif(not has_warp(), reason='NVIDIA Warp not installed (pip install -e ".[gpu]")')
    return [pytest.param(n, marks=skip) if "warp" in n else n for n in names]


@pytest.fixture(scope="session")
def cube():
    return load_shape({"name": "cube"})


def ray_backends(mesh):
    """Every exact ray caster of a mesh: name -> fn(origins, directions) -> (t, hit, normal); the warp
    ones (Warp's BVH on the CPU) only where Warp is installed."""
    from ddfbench.core.representation import Budget, FitData
    from ddfbench.models.mesh import MeshFamily
    from ddfbench.truth.oracle import Oracle

    def oracle_fn(backend):
        orc = Oracle(mesh, backend)

        def cast(o, d):
            t, tri, n = orc.first_hit(o, d)
            return t, tri >= 0, n

        return cast

    def family_fn(backend):
        rep = MeshFamily({"faces": 0, "backend": backend})
        rep.fit(FitData(samples=None, mesh=mesh, oracle=None), Budget())

        def cast(o, d):
            h = rep.intersect(o, d)
            return h.t, h.hit, h.normal

        return cast

    casters = {"oracle-open3d": oracle_fn("open3d"), "oracle-embree": oracle_fn("embree"),
               "mesh-family": family_fn("open3d")}
    if has_warp():
        casters.update({"oracle-warp": oracle_fn("warp"), "mesh-family-warp": family_fn("warp")})
    return casters


def assert_well_formed(t, hit, normal):
    """No NaN anywhere; hit <=> finite t >= 0; unit normals on hits, zero normals on misses."""
    assert not np.isnan(t).any() and np.isfinite(normal).all()
    assert np.array_equal(hit, np.isfinite(t))
    assert np.all(t[hit] >= 0)
    assert np.allclose(np.linalg.norm(normal[hit], axis=1), 1.0, atol=1e-5)
    assert np.all(normal[~hit] == 0)


def compose(*overrides: str, out_dir) -> dict:
    """The resolved run config (plain dict) for CLI-style overrides, as `python -m ddfbench` would build it
    (plugins.job_config: the plugins' experiments parts dropped, as the runner does first)."""
    import os

    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from omegaconf import OmegaConf

    conf = os.path.join(os.path.dirname(__file__), "..", "..", "conf")
    with initialize_config_dir(config_dir=os.path.abspath(conf), version_base="1.3"):
        cfg = hydra_compose("config", overrides=["scene=none", "eval=smoke", "threads=1", f"out_dir={out_dir}",
                                                 *overrides])
    return plugins.job_config(OmegaConf.to_container(cfg, resolve=True))
