"""Render artifacts: raw arrays for programs, PNG panels (reference | family | error) for people.

Files per camera c and requested output o, in the renders folder:
  cam{c}_{o}.npy            the family's array (depth: float32 t, inf on background; mask: bool;
  cam{c}_{o}_reference.npy  normal: float32 (H,W,3); shaded/path: float32 (H,W,3) linear radiance;
                            shadow: float32 share of lights blocked), and the oracle's
  cam{c}_{o}.png            oracle | family | error map, side by side

Error maps use fixed scales so maps of different families compare by eye: depth |Δt| / 0.05
(pixels only one render hits show full error), normal angle / 45°, mask XOR, image mean |Δ| / 0.25.
Radiance PNGs are clipped to [0, 1] and gamma-encoded with 1/2.2. PNGs are written with zlib.
"""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np

from ddfbench.render.compare import normal_angles_deg
from ddfbench.render.integrator import Frames

DEPTH_ERROR_SCALE = 0.05
NORMAL_ERROR_SCALE_DEG = 45.0
IMAGE_ERROR_SCALE = 0.25
_BACKGROUND = np.array([0.18, 0.18, 0.22])


def write_png(path: str, rgb: np.ndarray) -> None:
    """Write an (H,W,3) uint8 image as an 8-bit RGB PNG."""
    rgb = np.ascontiguousarray(rgb, np.uint8)
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[i].tobytes() for i in range(h))  # filter type 0 per scanline

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))
    with open(path, "wb") as f:
        f.write(png)


def _to_uint8(rgb: np.ndarray) -> np.ndarray:
    return np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8)


def _heat(err: np.ndarray) -> np.ndarray:
    """Error in [0, 1] (H,W) → black, red, yellow, white (H,W,3)."""
    e = np.clip(err, 0, 1)[..., None] * 3
    return np.clip(np.concatenate([e, e - 1, e - 2], axis=-1), 0, 1)


def _grey(values: np.ndarray, mask: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Depth (H,W) → near bright, far dark; background colour where ~mask."""
    scaled = 1 - (values - lo) / max(hi - lo, 1e-9) * 0.8
    out = np.repeat(np.where(mask, scaled, 0)[..., None], 3, axis=-1)
    out[~mask] = _BACKGROUND
    return out


def _panels(ref: Frames, fam: Frames, c: int, output: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(reference, family, error) RGB float images of camera c for one output."""
    rm, fm = ref.mask[c], fam.mask[c]
    both, either = rm & fm, rm | fm
    if output == "depth":
        hits = np.concatenate([ref.depth[c][rm], fam.depth[c][fm]])
        lo, hi = (float(hits.min()), float(hits.max())) if len(hits) else (0.0, 1.0)
        err = (either & ~both).astype(float)
        err[both] = np.abs(fam.depth[c][both] - ref.depth[c][both]) / DEPTH_ERROR_SCALE
        return _grey(ref.depth[c], rm, lo, hi), _grey(fam.depth[c], fm, lo, hi), _heat(err)
    if output == "mask":
        return (np.repeat(rm[..., None], 3, -1).astype(float), np.repeat(fm[..., None], 3, -1).astype(float),
                _heat((rm ^ fm).astype(float)))
    if output == "normal":
        def colour(n: np.ndarray, m: np.ndarray) -> np.ndarray:
            return np.where(m[..., None], n * 0.5 + 0.5, _BACKGROUND)

        err = np.where(both, normal_angles_deg(fam.normal[c], ref.normal[c]) / NORMAL_ERROR_SCALE_DEG, 0)
        err = np.where(either & ~both, 1.0, err)
        return colour(ref.normal[c], rm), colour(fam.normal[c], fm), _heat(err)
    if output == "shadow":
        return (np.repeat(ref.shadow[c][..., None], 3, -1), np.repeat(fam.shadow[c][..., None], 3, -1),
                _heat(np.abs(fam.shadow[c] - ref.shadow[c])))
    r, f = np.clip(ref.images[output][c], 0, 1), np.clip(fam.images[output][c], 0, 1)
    return r ** (1 / 2.2), f ** (1 / 2.2), _heat(np.abs(f - r).mean(axis=-1) / IMAGE_ERROR_SCALE)


def _array(frames: Frames, c: int, output: str) -> np.ndarray:
    if output in frames.images:
        return frames.images[output][c]
    return {"depth": frames.depth, "mask": frames.mask, "normal": frames.normal, "shadow": frames.shadow}[output][c]


def write_renders(folder: str, reference: Frames, frames: Frames, outputs: frozenset[str]) -> list[str]:
    """Write every requested output of every camera (module docstring); return the file names."""
    os.makedirs(folder, exist_ok=True)
    names = []
    gap = 2
    for c in range(len(frames.depth)):
        for output in sorted(outputs):
            stem = f"cam{c}_{output}"
            np.save(os.path.join(folder, f"{stem}.npy"), _array(frames, c, output))
            np.save(os.path.join(folder, f"{stem}_reference.npy"), _array(reference, c, output))
            panels = _panels(reference, frames, c, output)
            h = panels[0].shape[0]
            spacer = np.ones((h, gap, 3))
            write_png(os.path.join(folder, f"{stem}.png"),
                      _to_uint8(np.concatenate([panels[0], spacer, panels[1], spacer, panels[2]], axis=1)))
            names += [f"{stem}.npy", f"{stem}_reference.npy", f"{stem}.png"]
    return names
