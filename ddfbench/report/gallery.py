"""The gallery figure of a report: what each family's shape looks like, beside the oracle's.

One row per model, one column per shape; each cell is four panels from camera 0 of the run's scene:
the oracle's render, the family's render, the per-pixel error map (the run's own renders PNG:
normals where the scene has them, else depth; error scales in ddfbench/render/images.py) and the
family's extracted mesh (reconstruction.ply) ray cast from the same camera and shaded by its facet
normals (a head light). A row whose run gave no result (an empty mesh or one off the shape) says "not
converged". Runs without renders are left out; a report with none gets no gallery. The figure has a one-line
title; CAPTION, what a cell shows, goes into the report beside it.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np

from ddfbench.report.records import no_result, no_result_label, shape_name

GALLERY = "gallery.png"
TITLE = "Gallery: oracle | family | error | extracted mesh, camera 0"
CAPTION = ("Each cell, camera 0: the oracle's render | the family's | the per-pixel error (normals: angle / 45°, "
           "depth: |Δt| / 0.05; black 0, white ≥ scale) | the extracted mesh shaded from the same camera; one row a "
           "model (the lowest seed with renders), one column a shape.")
OUTPUTS = ("normal", "depth")  # the render shown, first found
_BACKGROUND = np.array([0.18, 0.18, 0.22])
_MESH_COLOUR = np.array([0.85, 0.78, 0.62])


def _render_png(record: dict[str, Any]) -> str | None:
    """Camera 0's 'oracle | family | error' PNG of the first output in OUTPUTS, or None."""
    renders = (record.get("artifacts") or {}).get("renders")
    if record.get("status") != "ok" or not renders or record.get("_dir") is None:  # None: a compact record
        return None
    folder = os.path.join(record["_dir"], renders)
    for output in OUTPUTS:
        path = os.path.join(folder, f"cam0_{output}.png")
        if os.path.isfile(path):
            return path
    return None


def shaded_mesh_view(mesh_path: str | None, scene_cfg: dict[str, Any]) -> np.ndarray:
    """(H, W, 3) float image of the mesh at mesh_path seen from camera 0 of scene_cfg; background
    colour only where there is no mesh (missing file or no faces)."""
    import open3d as o3d
    import trimesh

    from ddfbench.render.scene import parse_scene
    from ddfbench.truth.oracle import open3d_scene

    camera = parse_scene(scene_cfg).cameras[0]
    image = np.broadcast_to(_BACKGROUND, (camera.height, camera.width, 3)).copy()
    if mesh_path and not os.path.isfile(mesh_path):  # named by its record but gone: its panel is blank, said so
        print(f"ddfbench.report: {mesh_path}: missing; its gallery panel is left blank", file=sys.stderr)
    mesh = trimesh.load(mesh_path, process=False) if mesh_path and os.path.isfile(mesh_path) else None
    if mesh is None or len(getattr(mesh, "faces", [])) == 0:
        return image
    scene = open3d_scene(mesh)
    origins, directions = camera.rays()
    hit = scene.cast_rays(o3d.core.Tensor(np.concatenate([origins, directions], 1)))
    t = hit["t_hit"].numpy()
    normals = hit["primitive_normals"].numpy()
    cosine = np.abs(np.sum(normals * directions, axis=1))  # head light: facets facing the camera are bright
    shade = (0.25 + 0.75 * cosine)[:, None] * _MESH_COLOUR
    flat = image.reshape(-1, 3)
    flat[np.isfinite(t)] = shade[np.isfinite(t)]
    return flat.reshape(image.shape)


def _cells(records: list[dict[str, Any]]) -> dict[tuple[str, str], dict[str, Any]]:
    """(model, shape) → the record shown there: the ok record with renders of the lowest seed."""
    cells: dict[tuple[str, str], dict[str, Any]] = {}
    shown = [rec for rec in records if _render_png(rec) is not None]  # ok runs (a failed one may hold seed='abc')
    for rec in sorted(shown, key=lambda r: int((r.get("config") or {}).get("seed", 0))):
        cells.setdefault((str(rec.get("model")), shape_name(rec)), rec)
    return cells


def _strip(record: dict[str, Any]) -> tuple[np.ndarray, str]:
    """The cell's four panels side by side (H, 4W, 3) and the render's output name."""
    import matplotlib.image as mpimg

    png = _render_png(record)
    assert png is not None
    panels = mpimg.imread(png)[..., :3].astype(float)
    recon = (record.get("artifacts") or {}).get("reconstruction")
    mesh = shaded_mesh_view(os.path.join(record["_dir"], recon) if recon else None,
                            (record.get("config") or {}).get("scene") or {})
    output = os.path.basename(png)[len("cam0_"):-len(".png")]
    spacer = np.ones((panels.shape[0], 2, 3))  # the renders PNG's own gap between panels
    return np.concatenate([panels, spacer, mesh], axis=1), output


def _label(record: dict[str, Any]) -> str:
    metrics = record.get("metrics") or {}
    if metrics.get("empty_reconstruction"):
        return "empty mesh"
    chamfer = metrics.get("chamfer_l2")
    return f"CD-L2 {chamfer * 1e3:.3g} ×10⁻³" if isinstance(chamfer, (int, float)) else ""


def row_label(model: str, cells: dict[tuple[str, str], dict[str, Any]]) -> str:
    """A row's label: the model, marked "not converged" where every run it shows gave no result (empty or off the
    shape), "no result in k of n" where some did."""
    shown = [no_result(rec) for (m, _), rec in cells.items() if m == model]
    if not any(shown):
        return model
    return f"{model}\n({no_result_label(sum(shown), len(shown))})"


def write_gallery(records: list[dict[str, Any]], out_dir: str) -> str | None:
    """Write out_dir/gallery.png from the records that have renders; return its path (None: no renders)."""
    cells = _cells(records)
    if not cells:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = sorted({m for m, _ in cells})
    shapes = sorted({s for _, s in cells})
    fig, axes = plt.subplots(len(models), len(shapes), figsize=(5.6 * len(shapes), 1.6 * len(models) + 0.7),
                             squeeze=False, layout="constrained")
    for i, model in enumerate(models):
        for j, shape in enumerate(shapes):
            ax = axes[i][j]
            ax.set_xticks([])
            ax.set_yticks([])
            rec = cells.get((model, shape))
            if rec is None:
                ax.set_axis_off()
                continue
            strip, output = _strip(rec)
            ax.imshow(strip, interpolation="nearest")
            if i == 0:
                ax.set_title(shape, fontsize=11, fontweight="bold")
            ax.set_xlabel(f"{output}: {_label(rec)}", fontsize=8, labelpad=2)
            if j == 0:
                label = row_label(model, cells)
                ax.set_ylabel(label, fontsize=10, color="firebrick" if label != model else "black")
    fig.suptitle(TITLE, fontsize=10)
    path = os.path.join(out_dir, GALLERY)
    fig.savefig(path, dpi=150)
    plt.close(fig)
    return path
