"""The benchmark's outputs: a markdown table (one block per section) and the JSON document."""

from __future__ import annotations

import json
import math
import os
from typing import Any

from ddfbench.core.atomic import write_atomic


def number(v: float) -> str:
    """A figure for a table: 3 significant digits, or exponent notation below 1e-3."""
    if v is None or not math.isfinite(v):
        return str(v)
    return f"{v:.3g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.2e}"


def to_markdown(doc: dict[str, Any]) -> str:
    env, opt = doc["env"], doc["options"]
    lines = [
        "# ddfbench performance",
        "",
        f"`{doc['command']}` — device **{opt['device']}**{' (' + env['gpu'] + ')' if env.get('gpu') else ''}, "
        f"cpu {env.get('cpu')} × {env.get('cpu_count')}, torch threads {env.get('threads')}, sizes {opt['sizes']}, "
        f"repeats {opt['repeats']} (warm-up {opt['warmup']}), total {doc['total_s']:.0f} s, git {env.get('git_sha')}, "
        f"load average at start {doc.get('load_average_start')}"
        f"{', glibc heap keeps freed blocks (ddfbench.core.heap)' if env.get('glibc_heap_kept') else ''}.",
        "",
        "Every figure stands beside a reference measured in the same process; the ratio is what to quote "
        "(absolute times on a shared machine are noisy). Warm figures are medians of the repeats; each row "
        "names the device and precision it is from. ratio = value / reference unless the note says otherwise.",
    ]
    for i, (name, sec) in enumerate(doc["sections"].items(), 1):
        lines += ["", f"## {i}. {name} ({sec['seconds']:.0f} s)", ""]
        if sec["error"]:
            lines.append(f"**failed**: {sec['error']}")
            continue
        lines += ["| measure | value | reference | reference value | ratio | target | met | device | precision | "
                  "note |", "|---|---|---|---|---|---|---|---|---|---|"]
        for r in sec["rows"]:
            met = "" if r["met"] is None else ("yes" if r["met"] else "**no**")
            lines.append(f"| {r['measure']} | {number(r['value'])} {r['unit']} | {r['reference']} | "
                         f"{number(r['reference_value'])} | {number(r['ratio'])} | {r['target'] or ''} | {met} | "
                         f"{r['device']} | {r['precision']} | {r['note']} |")
        if sec["notes"]:
            lines += [""] + [f"- {note}" for note in sec["notes"]]
    return "\n".join(lines) + "\n"


def write(doc: dict[str, Any], out_dir: str, stem: str) -> tuple[str, str]:
    """Write <stem>.md and <stem>.json into out_dir (each whole or not at all: core.atomic)."""
    os.makedirs(out_dir, exist_ok=True)
    paths = []
    for ext, text in (("md", to_markdown(doc)), ("json", json.dumps(doc, indent=1, allow_nan=True) + "\n")):
        paths.append(write_atomic(os.path.join(out_dir, f"{stem}.{ext}"), lambda fh, text=text: fh.write(text)))
    return paths[0], paths[1]
