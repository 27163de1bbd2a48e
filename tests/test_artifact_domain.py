"""Every saved artifact holds the field domain it was built for: load takes it, and a caller expecting
another domain gets a one-line InputError naming the file and both values (the mesh's .ply holds none)."""

import json

import numpy as np
import pytest
import torch
import trimesh

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF
from ddfbench.models import available_families, load_family

STORING = [f for f in ("ddf", "neural_sdf", "gan_sdf", "grid_sdf") if f in available_families()]


def saved(family: str, domain: float, tmp_path) -> str:
    """An unfitted artifact of `family` built for `domain` (a grid of zeros for grid_sdf), saved under tmp_path."""
    cfg = {"resolution": 4} if family == "grid_sdf" else {}
    rep = load_family(family)(cfg, domain)
    if family == "grid_sdf":
        rep._set_grid(np.zeros((4, 4, 4), np.float32))
    return rep.save(str(tmp_path / family))


@pytest.mark.parametrize("family", STORING)
def test_load_takes_the_stored_domain_and_refuses_another(family, tmp_path):
    path = saved(family, 0.7, tmp_path)
    assert load_family(family).load(path).domain == 0.7
    assert load_family(family).load(path, domain=0.7).domain == 0.7
    with pytest.raises(InputError, match=rf"{family} artifact .*{family}.*: saved with domain 0.7, loaded with domain 0.6$"):
        load_family(family).load(path, domain=0.6)


@pytest.mark.skipif("ddf" not in STORING, reason="no ddf family")
def test_a_network_artifact_without_a_domain_is_refused(tmp_path):
    torch.save({"header": json.dumps({"family": "ddf", "cfg": {}}), "state_dict": {}}, tmp_path / "old.pt")
    with pytest.raises(InputError, match="old.pt: its header stores no domain$"):
        load_family("ddf").load(str(tmp_path / "old.pt"))


def test_mesh_artifact_takes_the_callers_domain(tmp_path):
    rep = load_family("mesh")({"faces": 0}, 0.7)
    rep.mesh = trimesh.creation.box()
    path = rep.save(str(tmp_path / "mesh"))
    assert load_family("mesh").load(path, domain=0.7).domain == 0.7
    assert load_family("mesh").load(path).domain == BOX_HALF
