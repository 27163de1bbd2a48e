"""Reading a sampler's config: every key required, no unknown keys, one-line InputError per bad value."""

from __future__ import annotations

import numbers
from typing import Any, Iterable, Mapping

from ddfbench.core.errors import InputError, checked_int


def check_keys(cfg: Mapping[str, Any], allowed: Iterable[str]) -> None:
    """Every key of `allowed` present in cfg (besides `strategy`), nothing else."""
    allowed = set(allowed) | {"strategy"}
    strategy = cfg.get("strategy")
    unknown = sorted(set(cfg) - allowed)
    missing = sorted(allowed - set(cfg))
    if unknown:
        raise InputError(f"sampling={strategy}: unknown key(s) {', '.join(unknown)} (valid: {', '.join(sorted(allowed))})")
    if missing:
        raise InputError(f"sampling={strategy}: missing key(s) {', '.join(missing)} (see conf/sampling/{strategy}.yaml)")


def count(cfg: Mapping[str, Any], key: str, minimum: int = 1) -> int:
    """sampling.<key> as an integer >= minimum (an integral float such as 10.0 is accepted)."""
    return checked_int(cfg[key], f"sampling.{key}", minimum)


def positive(cfg: Mapping[str, Any], key: str) -> float:
    """A finite number > 0."""
    v = cfg[key]
    if not (isinstance(v, numbers.Real) and not isinstance(v, bool) and 0 < float(v) < float("inf")):
        raise InputError(f"sampling.{key}={v!r}: must be a number > 0")
    return float(v)


def choice(cfg: Mapping[str, Any], key: str, options: Iterable[str]) -> str:
    """One of `options`."""
    options = list(options)
    v = cfg[key]
    if v not in options:
        raise InputError(f"sampling.{key}={v!r}: must be one of {' | '.join(options)}")
    return str(v)


def number_list(cfg: Mapping[str, Any], key: str) -> list[float]:
    """A non-empty list of numbers > 0."""
    v = cfg[key]
    if isinstance(v, numbers.Real):
        v = [v]
    try:
        out = [float(s) for s in v]
    except (TypeError, ValueError):
        out = []
    if not out or not all(0 < s < float("inf") for s in out):
        raise InputError(f"sampling.{key}={v!r}: must be a non-empty list of numbers > 0")
    return out


def flag(cfg: Mapping[str, Any], key: str) -> bool:
    """true or false."""
    v = cfg[key]
    if not isinstance(v, bool):
        raise InputError(f"sampling.{key}={v!r}: must be true or false")
    return v


def share(cfg: Mapping[str, Any], key: str) -> float:
    """A number in [0, 1)."""
    v = cfg[key]
    if not (isinstance(v, numbers.Real) and not isinstance(v, bool) and 0 <= float(v) < 1):
        raise InputError(f"sampling.{key}={v!r}: must be a number in [0, 1)")
    return float(v)
