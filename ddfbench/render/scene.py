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

from ddfbench.core import plugins
from ddfbench.core.errors import InputError, checked_int
from ddfbench.render.camera import Camera, orbit_cameras

OUTPUTS = ("depth", "mask", "normal", "shaded", "shadow", "path")
BASE_SCENE = "depth"  # conf/scene/depth.yaml declares every key a scene has, with its default; presets extend it
OPTIONAL_CAMERA_KEYS = ("look_at", "positions")  # cameras.look_at (default the origin), cameras.positions (or an orbit)
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


def _int(cfg: Mapping[str, Any], key: str, least: int, label: str = "scene") -> int:
    return checked_int(cfg[key], f"{label}.{key}", least)


def _positive(cfg: Mapping[str, Any], key: str, upper: float = math.inf, label: str = "scene") -> float:
    value, name = cfg[key], f"{label}.{key}"
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}={value!r}: expected a number") from None
    if not (0 < x < upper):
        raise InputError(f"{name}={value!r}: expected a number in (0, {upper})")
    return x


def _light(cfg: Any, i: int) -> Light:
    if not isinstance(cfg, Mapping):
        raise InputError(f"scene.lights[{i}]={cfg!r}: expected a mapping with type, direction|position, intensity")
    kind = cfg.get("type")
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
    if "intensity" not in cfg:
        raise InputError(f"scene.lights[{i}]: a {kind} light needs 'intensity'")
    intensity = _rgb(cfg["intensity"], f"lights[{i}].intensity")
    return Light(kind, vector, intensity)


def _cameras(cfg: Mapping[str, Any], width: int, height: int) -> tuple[Camera, ...]:
    fov = _positive(cfg, "fov_deg", upper=180.0, label="scene.cameras")
    radius = _positive(cfg, "radius", label="scene.cameras")
    look_at = np.asarray(_vec3(cfg["look_at"], "cameras.look_at") if "look_at" in cfg else (0.0, 0.0, 0.0))
    up = np.asarray(_vec3(cfg["up"], "cameras.up"))
    if not np.any(up):
        raise InputError("scene.cameras.up: zero vector")
    if cfg.get("positions"):
        positions = [_vec3(p, f"cameras.positions[{i}]") for i, p in enumerate(_list(cfg["positions"], "cameras.positions"))]
        cams = tuple(Camera(np.asarray(p), look_at, fov, width, height, up) for p in positions)
    else:
        n = _int(cfg, "n", 1, label="scene.cameras")
        elevation = float(cfg["elevation_deg"])
        if not -89.0 <= elevation <= 89.0:
            raise InputError(f"scene.cameras.elevation_deg={elevation}: expected a value in [-89, 89]")
        azimuth = float(cfg["azimuth_deg"])
        cams = orbit_cameras(n, radius, elevation, azimuth, fov, width, height, look_at, up)
    for i, cam in enumerate(cams):
        if np.allclose(cam.position, cam.look_at):
            raise InputError(f"scene.cameras: camera {i} sits on its look_at point")
    return cams


def declared_scene(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """cfg overlaid on the keys conf/scene/depth.yaml declares (the one source of scene defaults), nested
    mappings (cameras, timing) key by key; a key no scene declares is a one-line InputError naming it."""
    base = plugins.defaults("scene", BASE_SCENE)
    plugins.strict_keys("scene", cfg, base)
    out = {**base, **cfg}
    for key in ("cameras", "timing"):
        given = out[key] if out[key] is not None else {}
        if not isinstance(given, Mapping):
            raise InputError(f"scene.{key}={given!r}: expected a mapping ({', '.join(sorted(base[key]))})")
        known = {**base[key], **dict.fromkeys(OPTIONAL_CAMERA_KEYS if key == "cameras" else ())}
        plugins.strict_keys(f"scene.{key}", given, known)
        out[key] = {**base[key], **given}
    return out


def parse_scene(cfg: Mapping[str, Any]) -> Scene:
    """Validate a scene config (the `scene` node as a mapping; keys it leaves out take conf/scene/depth.yaml's
    values) into a Scene; InputError on an unknown key or a bad value."""
    cfg = declared_scene(cfg)
    outputs = [str(o) for o in (cfg["outputs"] or [])]
    unknown = sorted(set(outputs) - set(OUTPUTS))
    if unknown:
        raise InputError(f"scene.outputs: unknown {unknown} (choose from {', '.join(OUTPUTS)})")
    if not outputs:
        raise InputError("scene.outputs: empty; name at least one of " + ", ".join(OUTPUTS))
    if "shadow" in outputs and not {"shaded", "path"} & set(outputs):
        raise InputError("scene.outputs: 'shadow' needs 'shaded' or 'path' (shadows darken a shaded image)")
    width, height = _int(cfg, "width", 1), _int(cfg, "height", 1)
    timing = cfg["timing"]
    return Scene(
        name=str(cfg["name"]),
        outputs=frozenset(outputs),
        width=width,
        height=height,
        spp=_int(cfg, "spp", 1),
        max_depth=_int(cfg, "max_depth", 1),
        cameras=_cameras(cfg["cameras"], width, height),
        lights=tuple(_light(c, i) for i, c in enumerate(_list(cfg["lights"] or [], "lights"))),
        albedo=_albedo(cfg["albedo"]),
        background=_rgb(cfg["background"], "background"),
        environment=_rgb(cfg["environment"], "environment"),
        ray_offset=_positive(cfg, "ray_offset", upper=0.1),
        chunk=_int(cfg, "chunk", 1),
        repeats=_int(timing, "repeats", 1, label="scene.timing"),
        warmup=_int(timing, "warmup", 0, label="scene.timing"),
        timing_max_seconds=_positive(timing, "max_seconds", label="scene.timing"),
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
