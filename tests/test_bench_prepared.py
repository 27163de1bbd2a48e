"""ddfbench.bench.prepared: a network or mesh made once is saved and loaded back unchanged by a later call,
a changed recipe makes a new file, and without the `prepared` key nothing is written."""

import json
import os

import numpy as np
import pytest
import torch
import trimesh

from ddfbench.bench import prepared
from ddfbench.bench.context import model_preset
from ddfbench.core.errors import InputError
from ddfbench.models.neural_sdf import NeuralSDF


def _make(calls: list):
    def make():
        calls.append(1)
        torch.manual_seed(len(calls))
        rep = NeuralSDF(model_preset("neural_sdf_tuned", width=16, depth=2))
        return rep, {"fit_steps": 7}
    return make


def test_a_network_is_made_once_and_loaded_back_equal(tmp_path):
    sizes, calls = {"prepared": str(tmp_path / "p")}, []
    spec = {"cfg": {"width": 16}, "steps": 7}
    rep, info = prepared.artifact(sizes, "nsdf", spec, NeuralSDF, _make(calls))
    again, info2 = prepared.artifact(sizes, "nsdf", spec, NeuralSDF, _make(calls))
    assert len(calls) == 1 and info2["fit_steps"] == 7 and info2["prepared"].startswith("nsdf-")
    # the process that made it names it as a later one that loads it does (bench.repeats pools only the same names)
    assert info["prepared"] == info2["prepared"] and info["fit_steps"] == 7
    x = torch.rand(64, 3) - 0.5
    with torch.no_grad():
        assert torch.equal(rep.field(x), again.field(x))
    other, _ = prepared.artifact(sizes, "nsdf", {**spec, "steps": 8}, NeuralSDF, _make(calls))  # another recipe
    assert len(calls) == 2 and len([f for f in os.listdir(tmp_path / "p") if f.endswith(".json")]) == 2
    with torch.no_grad():
        assert not torch.equal(rep.field(x), other.field(x))


def test_without_the_key_nothing_is_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    calls = []
    prepared.artifact({"prepared": None}, "nsdf", {}, NeuralSDF, _make(calls))
    prepared.artifact({}, "nsdf", {}, NeuralSDF, _make(calls))
    assert len(calls) == 2 and os.listdir(tmp_path) == []


def test_a_missing_artifact_file_is_a_one_line_error(tmp_path):
    sizes, calls = {"prepared": str(tmp_path)}, []
    prepared.artifact(sizes, "nsdf", {}, NeuralSDF, _make(calls))
    stem = prepared.file_stem(str(tmp_path), "nsdf", {})
    os.remove(os.path.join(tmp_path, json.load(open(f"{stem}.json"))["path"]))
    with pytest.raises(InputError, match="nsdf-.*unreadable"):
        prepared.artifact(sizes, "nsdf", {}, NeuralSDF, _make(calls))


def test_a_mesh_round_trips(tmp_path):
    sizes, made = {"prepared": str(tmp_path)}, []
    box = trimesh.creation.box()

    def make():
        made.append(1)
        return box

    first = prepared.mesh(sizes, "box-lod", {"faces": 12}, make)
    second = prepared.mesh(sizes, "box-lod", {"faces": 12}, make)
    assert len(made) == 1 and first is box
    assert np.array_equal(second.faces, box.faces) and np.allclose(second.vertices, box.vertices)
