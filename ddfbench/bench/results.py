"""What a benchmark section hands back: comparison rows (a figure beside its same-process reference,
their ratio, the target) and free-form details (raw timings, counts) for the JSON file.
"""

from __future__ import annotations

import math
import operator
from dataclasses import asdict, dataclass, field
from typing import Any

_OPS = {">=": operator.ge, "<=": operator.le}


def precision_of(contestant: str) -> str:
    """A row's precision from the contestant it names ("ddf_bf16_compiled" -> "bf16", else "fp32")."""
    return "bf16" if "bf16" in contestant else "fp32"


@dataclass
class Target:
    """A goal on the row's ratio (on="ratio") or on its value (on="value"): op ">=" or "<=", bound."""

    op: str
    bound: float
    on: str = "ratio"

    def text(self, unit: str) -> str:
        return f"ratio {self.op} {self.bound:g}" if self.on == "ratio" else f"{self.op} {self.bound:g} {unit}"


@dataclass
class Row:
    """One figure and its reference, measured side by side in the same process.

    ratio = value / reference_value, or reference_value / value when `inverse` (so that above 1 is
    always "better than the reference" for the stated meaning); ratio_means says which.
    """

    section: str
    measure: str
    value: float
    unit: str
    reference: str
    reference_value: float
    ratio: float
    ratio_means: str
    device: str
    precision: str = "fp32"
    threads: int = 0
    target: str | None = None
    met: bool | None = None
    note: str = ""


def compare(section: str, measure: str, value: float, unit: str, reference: str, reference_value: float, *,
            device: str, threads: int, precision: str = "fp32", inverse: bool = False,
            target: Target | None = None, note: str = "") -> Row:
    """A Row with its ratio and, when a target is given, whether it is met."""
    value, reference_value = float(value), float(reference_value)
    num, den = (reference_value, value) if inverse else (value, reference_value)
    ratio = num / den if den > 0 else math.inf
    means = "reference / value" if inverse else "value / reference"
    met = None
    if target is not None:
        met = bool(_OPS[target.op](ratio if target.on == "ratio" else value, target.bound))
    return Row(section, measure, value, unit, reference, reference_value, ratio, means, device, precision,
               int(threads), target.text(unit) if target else None, met, note)


@dataclass
class SectionResult:
    """rows: the comparisons; details: raw figures for the JSON; notes: one-line remarks for the table
    (a family skipped, a run that failed); seconds: the section's wall time; error: why it failed as a whole."""

    rows: list[Row] = field(default_factory=list)
    details: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"rows": [asdict(r) for r in self.rows], "details": self.details, "notes": self.notes,
                "seconds": self.seconds, "error": self.error}
