"""Shape families: one module per family, each exposing its Representation subclass as FAMILY.

A family is registered by being here (with its conf/model/<family>.yaml); what the rest of the program
needs to know about it is on the class: sample_kind, learned, configure (see ddfbench.core.representation).
"""

from __future__ import annotations

import importlib
import pkgutil

from ddfbench.core.errors import InputError
from ddfbench.core.representation import Representation


def available_families() -> list[str]:
    """Names of the family modules in this package."""
    return sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))


def load_family(name: str) -> type[Representation]:
    """The Representation class of family `name` (module ddfbench.models.<name>)."""
    if name not in available_families():
        raise InputError(f"model.family '{name}': unknown family (available: {', '.join(available_families())})")
    module = importlib.import_module(f"ddfbench.models.{name}")
    return module.FAMILY


def learned_families() -> list[str]:
    """The registered families whose fit trains something (Representation.learned)."""
    return [name for name in available_families() if load_family(name).learned]
