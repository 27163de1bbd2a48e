"""A committed report folder's small JSON files (a re-measurement's header, a tuning study's study.json), read with
the keys a reader needs checked. It lives in the report stage, which alone reads them: a helper added to a module
the fits import would mark every suite report stale (`python -m ddfbench.suite status`) for a change no fit ran."""

from __future__ import annotations

import json
from typing import Any

from ddfbench.core.errors import InputError, first_line


def checked_json_object(path: str, needs: dict[str, type]) -> dict[str, Any]:
    """The JSON object in the file at path, with a value of the given type at each key of `needs`; an InputError
    naming the file when it is unreadable, not JSON or not such an object."""
    try:
        with open(path, encoding="utf-8") as fh:
            found = json.load(fh)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: not a readable JSON file ({first_line(exc)})") from exc
    if not isinstance(found, dict) or any(not isinstance(found.get(key), kind) for key, kind in needs.items()):
        keys = ", ".join(f"{key} (a {kind.__name__})" for key, kind in needs.items())
        raise InputError(f"{path}: needs a JSON object with {keys}")
    return found
