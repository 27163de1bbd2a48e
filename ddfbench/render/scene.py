"""Scene configs: parse and validate them, and turn them into the set of passes to run.

A scene asks for outputs by name (OUTPUTS); `plan_passes` is the one pure function that decides
which ray queries those outputs need, so nothing is computed that no output uses:

- primary rays always (they give depth and mask);
- normals at primary hits only if an output shows them or shades with them (normal, shaded, path);
- shadow rays only if shading is on (shaded or path), the scene has lights and `shadow` is asked for;
- bounce rays only for `path` with max_depth > 1 (max_depth counts path vertices: 1 = direct light).

Units: the normalized frame of the GT mesh (unit cube); angles in degrees; radiance is linear.
Light conventions: a directional light's `direction` is where its light travels (toward the scene),
`intensity` the irradiance on a surface facing it; a point light's `intensity` is radiant intensity,
so irradiance falls off as intensity / r².
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from ddfbench.errors import InputError, checked_int
from ddfbench.render.camera import Camera, orbit_cameras

OUTPUTS = ("depth", "mask", "normal", "shaded", "shadow", "path")
LIGHT_TYPES = ("directional", "point")


@dataclass(frozen=True)
class Light:
    """kind: "directional" | "point"; vector: travel direction (unit) or position; color: (3,) radiometric scale."""

    kind: str
    vector: tuple[float, float, float]
    color: tuple[float, float, float]


@dataclass(frozen=True)
class Scene:
    """A validated scene: what to render, from where, under which light."""

    name: str
    outputs: frozenset[str]
    width: int
    height: int
    spp: int
    max_depth: int
    cameras: tuple[Camera, ...]
    lights: tuple[Light, ...]
    albedo: tuple[float, float, float]
    background: tuple[float, float, float]  # radiance of camera rays that miss
    environment: tuple[float, float, float]  # radiance of bounce rays that escape
    ray_offset: float  # secondary-ray origin offset along the normal (normalized-frame units)
    chunk: int  # most rays per intersect call
    repeats: int  # timed warm renders
    warmup: int  # untimed renders between the cold one and the timed ones
    timing_max_seconds: float  # stop warm-up and repeats once this much render time is spent (>= 1 repeat)


@dataclass(frozen=True)
class Passes:
    """Which ray queries a render runs (see the module docstring for the rules)."""

    normals: bool
    shaded: bool
    path: bool
    shadow_rays: bool
    bounce_rays: bool


def plan_passes(scene: Scene) -> Passes:
    """The passes `scene` needs; primary rays are always cast."""
    shading = bool({"shaded", "path"} & scene.outputs)
    return Passes(
        normals="normal" in scene.outputs or shading,
        shaded="shaded" in scene.outputs,
        path="path" in scene.outputs,
        shadow_rays=shading and bool(scene.lights) and "shadow" in scene.outputs,
        bounce_rays="path" in scene.outputs and scene.max_depth > 1,
    )


# ---- parsing --------------------------------------------------------------------------------------
def _rgb(value: Any, key: str) -> tuple[float, float, float]:
    """A scalar (grey) or a 3-vector, finite and >= 0."""
    if isinstance(value, (int, float)):
        value = [value] * 3
    try:
        rgb = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f"scene.{key}={value!r}: expected a number or three numbers") from None
    if len(rgb) != 3 or not all(math.isfinite(v) and v >= 0 for v in rgb):
        raise InputError(f"scene.{key}={list(rgb)}: expected one or three finite numbers >= 0")
    return rgb  # type: ignore[return-value]


def _vec3(value: Any, key: str) -> tuple[float, float, float]:
    try:
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        raise InputError(f"scene.{key}={value!r}: expected three numbers") from None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise InputError(f"scene.{key}={list(v)}: expected three finite numbers")
    return v  # type: ignore[return-value]


def _int(cfg: Mapping[str, Any], key: str, default: int, least: int) -> int:
    return checked_int(cfg.get(key, default), f"scene.{key}", least)


def _positive(cfg: Mapping[str, Any], key: str, default: float, upper: float = math.inf) -> float:
    value = cfg.get(key, default)
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"scene.{key}={value!r}: expected a number") from None
    if not (0 < x < upper):
        raise InputError(f"scene.{key}={value!r}: expected a number in (0, {upper})")
    return x


def _light(cfg: Any, i: int) -> Light:
    if not isinstance(cfg, Mapping):
        raise InputError(f"scene.lights[{i}]={cfg!r}: expected a mapping with type, direction|position, intensity")
    kind = str(cfg.get("type", ""))
    if kind not in LIGHT_TYPES:
        raise InputError(f"scene.lights[{i}].type={kind!r}: unknown (directional | point)")
    key = "direction" if kind == "directional" else "position"
    if key not in cfg:
        raise InputError(f"scene.lights[{i}]: a {kind} light needs '{key}'")
    vector = _vec3(cfg[key], f"lights[{i}].{key}")
    if kind == "directional":
        norm = math.sqrt(sum(x * x for x in vector))
        if norm == 0:
            raise InputError(f"scene.lights[{i}].direction: zero vector")
        vector = tuple(x / norm for x in vector)  # type: ignore[assignment]
    intensity = _rgb(cfg.get("intensity", 1.0), f"lights[{i}].intensity")
    return Light(kind, vector, intensity)


def _cameras(cfg: Any, width: int, height: int) -> tuple[Camera, ...]:
    if not isinstance(cfg, Mapping):
        raise InputError(f"scene.cameras={cfg!r}: expected a mapping (n, radius, elevation_deg, azimuth_deg, fov_deg, up)")
    fov = _positive(cfg, "fov_deg", 40.0, upper=180.0)
    radius = _positive(cfg, "radius", 2.0)
    look_at = np.asarray(_vec3(cfg.get("look_at", (0.0, 0.0, 0.0)), "cameras.look_at"))
    up = np.asarray(_vec3(cfg.get("up", (0.0, 1.0, 0.0)), "cameras.up"))
    if not np.any(up):
        raise InputError("scene.cameras.up: zero vector")
    if cfg.get("positions"):
        positions = [_vec3(p, f"cameras.positions[{i}]") for i, p in enumerate(_list(cfg["positions"], "cameras.positions"))]
        cams = tuple(Camera(np.asarray(p), look_at, fov, width, height, up) for p in positions)
    else:
        n = _int(cfg, "n", 2, 1)
        elevation = float(cfg.get("elevation_deg", 25.0))
        if not -89.0 <= elevation <= 89.0:
            raise InputError(f"scene.cameras.elevation_deg={elevation}: expected a value in [-89, 89]")
        azimuth = float(cfg.get("azimuth_deg", 30.0))
        cams = orbit_cameras(n, radius, elevation, azimuth, fov, width, height, look_at, up)
    for i, cam in enumerate(cams):
        if np.allclose(cam.position, cam.look_at):
            raise InputError(f"scene.cameras: camera {i} sits on its look_at point")
    return cams


def parse_scene(cfg: Mapping[str, Any]) -> Scene:
    """Validate a scene config (the `scene` node as a mapping) into a Scene; InputError on bad values."""
    outputs = [str(o) for o in (cfg.get("outputs") or [])]
    unknown = sorted(set(outputs) - set(OUTPUTS))
    if unknown:
        raise InputError(f"scene.outputs: unknown {unknown} (choose from {', '.join(OUTPUTS)})")
    if not outputs:
        raise InputError("scene.outputs: empty; name at least one of " + ", ".join(OUTPUTS))
    if "shadow" in outputs and not {"shaded", "path"} & set(outputs):
        raise InputError("scene.outputs: 'shadow' needs 'shaded' or 'path' (shadows darken a shaded image)")
    width, height = _int(cfg, "width", 64, 1), _int(cfg, "height", 64, 1)
    timing = cfg.get("timing") or {}
    if not isinstance(timing, Mapping):
        raise InputError(f"scene.timing={timing!r}: expected a mapping (repeats, warmup)")
    return Scene(
        name=str(cfg.get("name", "custom")),
        outputs=frozenset(outputs),
        width=width,
        height=height,
        spp=_int(cfg, "spp", 1, 1),
        max_depth=_int(cfg, "max_depth", 1, 1),
        cameras=_cameras(cfg.get("cameras") or {}, width, height),
        lights=tuple(_light(c, i) for i, c in enumerate(_list(cfg.get("lights") or [], "lights"))),
        albedo=_albedo(cfg.get("albedo", 0.8)),
        background=_rgb(cfg.get("background", 1.0), "background"),
        environment=_rgb(cfg.get("environment", 0.0), "environment"),
        ray_offset=_positive(cfg, "ray_offset", 1e-3, upper=0.1),
        chunk=_int(cfg, "chunk", 1 << 18, 1),
        repeats=_int(timing, "repeats", 3, 1),
        warmup=_int(timing, "warmup", 1, 0),
        timing_max_seconds=_positive(timing, "max_seconds", 20.0),
    )


def _list(value: Any, key: str) -> list[Any]:
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Sequence):
        raise InputError(f"scene.{key}={value!r}: expected a list")
    return list(value)


def _albedo(value: Any) -> tuple[float, float, float]:
    rgb = _rgb(value, "albedo")
    if max(rgb) > 1:
        raise InputError(f"scene.albedo={list(rgb)}: a diffuse albedo above 1 creates energy (use values in [0, 1])")
    return rgb
