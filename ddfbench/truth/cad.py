"""CAD-like shapes built by constructive solid geometry with manifold3d: sharp edges, holes, thin walls.

Each builder returns a raw watertight trimesh in the frame of the catalog's builders (sizes in units of about the
longest side, centred near the origin); normalization then scales the longest side to exactly 1 (the chain, 0.85
long and off-centre, is scaled by 1 / 0.85 and centred). manifold3d's booleans are exact
and always give a manifold result, which is why these are built with it and not with mesh booleans by hand.

    bracket            an L bracket (plate 0.08 thick) with a gusset and six bolt holes: genus 6
    gear               a 16-tooth spur gear, 0.25 thick, with a bore and four lightening holes: genus 5
    lattice            a cubic lattice of 4 x 4 x 4 cells of square struts (0.06): genus 176
    cup                a cylindrical cup of wall `wall` (0.01): a thin wall, genus 0
    perforated_plate   a 1 x 1 x `thickness` (0.03) plate with a 5 x 5 array of round holes: genus 25
    chain              two interlocked tori: two components, genus 1 each
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from ddfbench.core.errors import InputError


def _manifold():
    try:
        import manifold3d
    except ImportError as exc:
        raise InputError(f"the CAD shapes are built with manifold3d, which is not installed ({exc}): "
                         "pip install manifold3d") from None
    return manifold3d


def _trimesh(solid) -> trimesh.Trimesh:
    """manifold3d.Manifold -> trimesh (float64 vertices (V, 3), int64 faces (F, 3))."""
    mesh = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties[:, :3], np.float64),
                           np.asarray(mesh.tri_verts, np.int64), process=False)


def _bar(m, size: tuple[float, float, float], at: tuple[float, float, float]):
    return m.Manifold.cube(size, center=True).translate(at)


def _rod(m, radius: float, length: float, axis: str, at: tuple[float, float, float], segments: int = 48):
    """A cylinder of `radius` and `length` along `axis` ('x', 'y' or 'z') centred at `at`."""
    rod = m.Manifold.cylinder(length, radius, -1.0, segments, True)
    turn = {"x": (0.0, 90.0, 0.0), "y": (90.0, 0.0, 0.0), "z": (0.0, 0.0, 0.0)}[axis]
    return rod.rotate(turn).translate(at)


def bracket(thickness: float = 0.08, hole_radius: float = 0.05) -> trimesh.Trimesh:
    """An L bracket: a 1 x 0.6 base plate and a 0.6 x 0.6 upright, a triangular gusset, two bolt holes in the upright, four in the base."""
    m = _manifold()
    t = float(thickness)
    if not 0.0 < t < 0.3 or not 0.0 < hole_radius < 0.12:
        raise InputError(f"bracket: thickness {t:g} must be in (0, 0.3) and hole_radius {hole_radius:g} in (0, 0.12)")
    base = _bar(m, (1.0, 0.6, t), (0.0, 0.0, t / 2))
    upright = _bar(m, (t, 0.6, 0.6), (-0.5 + t / 2, 0.0, 0.3))
    gusset = m.Manifold.hull_points([(-0.5 + t, -0.02, t), (-0.5 + t, 0.02, t), (-0.1, -0.02, t), (-0.1, 0.02, t),
                                     (-0.5 + t, -0.02, 0.5), (-0.5 + t, 0.02, 0.5)])
    holes = [_rod(m, hole_radius, 0.4, "z", (x, y, 0.0)) for x in (0.15, 0.35) for y in (-0.18, 0.18)]
    holes += [_rod(m, hole_radius, 0.4, "x", (-0.5, y, 0.4)) for y in (-0.18, 0.18)]
    solid = m.Manifold.batch_boolean([base, upright, gusset], m.OpType.Add)
    return _trimesh(m.Manifold.batch_boolean([solid, *holes], m.OpType.Subtract).translate((0.0, 0.0, -0.3)))


def gear(teeth: int = 16, thickness: float = 0.25) -> trimesh.Trimesh:
    """A spur gear of outer radius 0.5 with `teeth` trapezoid teeth, a 0.1 bore and four 0.06 lightening holes."""
    m = _manifold()
    if not 6 <= int(teeth) <= 64 or not 0.0 < thickness <= 1.0:
        raise InputError(f"gear: teeth {teeth} must be in [6, 64] and thickness {thickness:g} in (0, 1]")
    root, tip, n = 0.42, 0.5, int(teeth)
    outline = []
    for k in range(n):
        a = 2 * math.pi * k / n
        for frac, r in ((0.0, root), (0.2, tip), (0.45, tip), (0.65, root)):
            outline.append((r * math.cos(a + frac * 2 * math.pi / n), r * math.sin(a + frac * 2 * math.pi / n)))
    body = m.CrossSection([outline]).extrude(float(thickness)).translate((0.0, 0.0, -float(thickness) / 2))
    holes = [_rod(m, 0.1, 2.0, "z", (0.0, 0.0, 0.0))]
    holes += [_rod(m, 0.06, 2.0, "z", (0.25 * math.cos(a), 0.25 * math.sin(a), 0.0))
              for a in np.linspace(0.0, 2 * math.pi, 4, endpoint=False)]
    return _trimesh(m.Manifold.batch_boolean([body, *holes], m.OpType.Subtract))


def lattice(cells: int = 4, strut: float = 0.06) -> trimesh.Trimesh:
    """A cubic lattice of cells^3 cells in the unit cube: (cells + 1)^2 square struts along each axis."""
    m = _manifold()
    n, s = int(cells), float(strut)
    if not 1 <= n <= 12 or not 0.0 < s < 1.0 / n:
        raise InputError(f"lattice: cells {n} must be in [1, 12] and strut {s:g} in (0, 1/cells)")
    ticks = np.linspace(-0.5 + s / 2, 0.5 - s / 2, n + 1)
    # struts along y and z are 0.9 and 0.8 as thick as those along x: no two faces coplanar, so the union's
    # edges and corners are ordinary (with equal struts, coincident faces leave pinched vertices)
    bars = []
    for u in ticks:
        for w in ticks:
            bars += [_bar(m, (1.0, s, s), (0.0, u, w)), _bar(m, (0.9 * s, 1.0 - 0.1 * s, 0.9 * s), (u, 0.0, w)),
                     _bar(m, (0.8 * s, 0.8 * s, 1.0 - 0.2 * s), (u, w, 0.0))]
    return _trimesh(m.Manifold.batch_boolean(bars, m.OpType.Add))


def cup(wall: float = 0.01, radius: float = 0.3, height: float = 1.0) -> trimesh.Trimesh:
    """A closed-bottom cylindrical cup of outer `radius`, `height` and wall (and floor) thickness `wall`."""
    m = _manifold()
    if not 0.0 < wall < radius < 0.5 or not 2 * radius <= height <= 1.0:
        raise InputError(f"cup: need 0 < wall {wall:g} < radius {radius:g} < 0.5 and 2 radius <= height {height:g} <= 1")
    outer = m.Manifold.cylinder(height, radius, -1.0, 128, True)
    inner = m.Manifold.cylinder(height, radius - wall, -1.0, 128, True).translate((0.0, 0.0, wall))
    return _trimesh(outer - inner)


def perforated_plate(thickness: float = 0.03, holes: int = 5, hole_radius: float = 0.06) -> trimesh.Trimesh:
    """A 1 x 1 x thickness plate with a holes x holes array of round through-holes."""
    m = _manifold()
    k = int(holes)
    if not 0.0 < thickness < 0.5 or not 1 <= k <= 20 or not 0.0 < hole_radius < 0.5 / k:
        raise InputError(f"perforated_plate: thickness {thickness:g}, holes {k}, hole_radius {hole_radius:g}: "
                         "need 0 < thickness < 0.5, 1 <= holes <= 20, 0 < hole_radius < 0.5 / holes")
    plate = _bar(m, (1.0, 1.0, float(thickness)), (0.0, 0.0, 0.0))
    centres = (np.arange(k) + 0.5) / k - 0.5
    drills = [_rod(m, hole_radius, 1.0, "z", (x, y, 0.0)) for x in centres for y in centres]
    return _trimesh(m.Manifold.batch_boolean([plate, *drills], m.OpType.Subtract))


def chain(major_radius: float = 0.25, minor_radius: float = 0.05) -> trimesh.Trimesh:
    """Two tori linked through each other: one in the xy plane, one in the xz plane shifted by major_radius."""
    m = _manifold()
    if not 0.0 < minor_radius < major_radius / 2:
        raise InputError(f"chain: need 0 < minor_radius {minor_radius:g} < major_radius {major_radius:g} / 2")
    ring = m.CrossSection.circle(float(minor_radius), 32).translate((float(major_radius), 0.0)).revolve(96)
    second = ring.rotate((90.0, 0.0, 0.0)).translate((float(major_radius), 0.0, 0.0))
    return _trimesh(ring + second)


CAD_BUILDERS = {"bracket": bracket, "gear": gear, "lattice": lattice, "cup": cup,
                "perforated_plate": perforated_plate, "chain": chain}
