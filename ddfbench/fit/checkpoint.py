"""Fit checkpoints: an interrupted fit goes on from its last checkpoint instead of starting over.

Some fits outlive the process that runs them: the thesis GAN's 40 epochs take ~4.5 h on one CPU
thread (1.65 s a step at batch 1024, ~9,750 steps on the bunny). The shared training loop
(ddfbench.fit.train.train_loop) saves, every `every_s` seconds of training, one file with everything the
rest of the fit depends on: the module's and optimizers' state, each random generator's state
(python, numpy, torch on the CPU and CUDA, and any torch.Generator a family draws its batches from),
the step, the training and probe seconds, the loss curve, the probes taken and those still to come.
A fit given the same checkpoint loads it and goes on: on the same machine, code and thread count the
result is bit-identical to an uninterrupted fit's (tests/test_checkpoint.py).

A file written by other code (its `tag`: code_fingerprint(), a hash of the package's source, so an
uncommitted edit counts), for another fit (the loop's label: family, seed, steps, device, threads,
torch version) or one that cannot be read is not loaded: the fit starts over and says so in the log.
A readable file of other code or another fit is not overwritten but set aside beside it, named by a hash
of its fit and tag (<path>.<12 hex>.pt), and a later load by that code for that fit takes it back: a rerun
by mistake on another thread count, say, costs no hours of a long fit.
A save that fails is logged and the fit goes on. The file holds tensors, numbers, strings and
containers only, and is read with weights_only=True (DESIGN.md, Safety). The runner keeps it at
<run dir>/fit_checkpoint.pt and deletes it once an ok record is written (and before a force=true rerun):
a run that failed after its fit resumes from the finished fit. The record's fit.resumed_at lists the
steps a fit resumed from.
"""

from __future__ import annotations

import glob
import hashlib
import logging
import os
import random
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import torch

from ddfbench.core.atomic import leftovers, write_atomic

log = logging.getLogger(__name__)

FILE = "fit_checkpoint.pt"
FORMAT = 2  # 2: loaded with weights_only=True (numpy RNG key as a list of ints)


@dataclass(frozen=True)
class Checkpoint:
    """Where a fit keeps its checkpoint, how often (seconds of training) and who writes it (`tag`)."""

    path: str
    every_s: float = 600.0
    tag: str = ""

    def save(self, state: Mapping[str, Any]) -> None:
        """Write `state` with this checkpoint's tag: a temporary file of this process, synced, then an atomic
        rename (core.atomic). A failure is logged, not raised: the fit goes on without that save."""
        try:
            write_atomic(self.path, lambda fh: torch.save({"format": FORMAT, "tag": self.tag, **state}, fh), "wb")
        except Exception as exc:  # a full disk, or a family's state that cannot be serialized
            log.warning("%s: checkpoint not saved (%s); the fit goes on", self.path, exc)

    def load(self, fit: str) -> dict[str, Any] | None:
        """The saved state of fit `fit` (the loop's label of what is trained), or None: no file, one that
        cannot be read, or one written by other code or for another fit (set aside, logged; the fit starts
        over). A checkpoint of this fit by this code that an earlier load set aside is taken back. Never
        raises: a file that cannot be moved is logged and the fit starts over."""
        state = self._read() if os.path.exists(self.path) else None
        if state is not None and state.get("tag") == self.tag and state.get("fit") == fit:
            return state
        try:
            if state is not None:
                aside = self._aside(str(state.get("fit")), str(state.get("tag")))
                os.replace(self.path, aside)
                log.warning("%s: written for %s by code %s, not %s by %s: set aside as %s, where a run of that "
                            "fit by that code finds it", self.path, state.get("fit"), state.get("tag"), fit,
                            self.tag, os.path.basename(aside))
            mine = self._aside(fit, self.tag)
            if os.path.exists(mine):
                os.replace(mine, self.path)
                state = self._read()
                if state is not None and state.get("tag") == self.tag and state.get("fit") == fit:
                    log.warning("%s: taken back from %s", self.path, os.path.basename(mine))
                    return state
        except OSError as exc:  # a read-only results folder, or another process moved the file first
            log.warning("%s: checkpoint not moved (%s)", self.path, exc)
        if os.path.exists(self.path) or state is not None:
            log.warning("%s: no checkpoint of %s by %s: the fit starts over", self.path, fit, self.tag)
        return None

    def _read(self) -> dict[str, Any] | None:
        """The file at self.path as a state dict of this format, or None (logged) when it is not one."""
        try:  # tensors, numbers, strings and containers only: a results folder may come from someone else
            state = torch.load(self.path, map_location="cpu", weights_only=True)
        except Exception as exc:  # truncated, corrupt or holding other objects: start over rather than fail the run
            log.warning("%s: unreadable, or of an older format (%s)", self.path, exc)
            return None
        if not isinstance(state, dict) or state.get("format") != FORMAT:
            log.warning("%s: of an older format", self.path)
            return None
        return state

    def _aside(self, fit: str, tag: str) -> str:
        """Where a checkpoint of fit `fit` by code `tag` waits while another fit uses self.path."""
        digest = hashlib.sha256("\n".join((fit, tag)).encode()).hexdigest()[:12]
        return f"{self.path}.{digest}.pt"

    def remove(self) -> None:
        """Delete the checkpoint, those set aside and any temporary file a killed save left."""
        stem = glob.escape(self.path)
        for path in (self.path, *leftovers(self.path), *glob.glob(f"{stem}.*.tmp"), *glob.glob(f"{stem}.*.pt")):
            if os.path.exists(path):
                os.remove(path)


def code_fingerprint(package: str = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))) -> str:
    """16 hex chars: sha256 over the package's .py files (relative path and bytes, sorted): the code a fit ran."""
    h = hashlib.sha256()
    for path in sorted(glob.glob(os.path.join(package, "**", "*.py"), recursive=True)):
        h.update(os.path.relpath(path, package).encode())
        with open(path, "rb") as fh:
            h.update(fh.read())
    return h.hexdigest()[:16]


def rng_state(device: str = "cpu") -> dict[str, Any]:
    """The global random generators' states: python, numpy (its MT19937 key as 624 ints, so the file loads
    with weights_only), torch CPU, and torch CUDA for a fit on `device` "cuda…" only (reading it would
    start a CUDA context in every CPU fit on a GPU machine)."""
    numpy = np.random.get_state(legacy=False)
    numpy["state"] = {"key": numpy["state"]["key"].tolist(), "pos": int(numpy["state"]["pos"])}
    return {"python": random.getstate(), "numpy": numpy, "torch": torch.get_rng_state(),
            "cuda": torch.cuda.get_rng_state_all() if device.startswith("cuda") else None}


def set_rng_state(state: Mapping[str, Any]) -> None:
    """Put back the generators' states that rng_state returned."""
    random.setstate(state["python"])
    numpy = dict(state["numpy"])
    numpy["state"] = {"key": np.asarray(numpy["state"]["key"], dtype=np.uint32), "pos": numpy["state"]["pos"]}
    np.random.set_state(numpy)
    torch.set_rng_state(state["torch"])
    if state.get("cuda") is not None:
        torch.cuda.set_rng_state_all(state["cuda"])


def state_of(objects: Mapping[str, Any]) -> dict[str, Any]:
    """{name: state} of modules, optimizers (state_dict) and torch.Generators (get_state)."""
    return {name: obj.get_state() if isinstance(obj, torch.Generator) else obj.state_dict()
            for name, obj in objects.items()}


def restore(objects: Mapping[str, Any], states: Mapping[str, Any]) -> None:
    """Put each saved state back into the object of the same name (see state_of)."""
    for name, obj in objects.items():
        if isinstance(obj, torch.Generator):
            obj.set_state(states[name])
        else:
            obj.load_state_dict(states[name])
