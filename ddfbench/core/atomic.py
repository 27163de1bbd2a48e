"""Files written whole or not at all: a reader, or a process killed midway, finds the old file or the whole new one.

`write_atomic` fills a temporary file beside the target, syncs it to disk and renames it over the target. Run
records, datasets, fit checkpoints, compact records, bench tables and mesh files are written through it;
`write_atomic_named` does the same for writers that take only a file name (torch.save and np.savez: the model
artifacts). This module imports nothing of ddfbench, so any layer may use it.
"""

from __future__ import annotations

import contextlib
import glob
import os
import tempfile
from typing import IO, Any, Callable


def _read_umask() -> int:
    """The process's umask (read once, at import, before any thread: reading it means setting it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


UMASK = _read_umask()


def _publish(tmp: str, path: str, fill: Callable[[], None]) -> str:
    """Run fill(), which writes tmp whole and syncs it, then rename tmp over path; return path. A failure of either
    removes tmp and raises."""
    try:
        fill()
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def write_atomic(path: str, write: Callable[[IO[Any]], None], mode: str = "w") -> str:
    """Fill a temporary file in path's folder by write(fh) (mode "w" text, "wb" bytes), fsync it, then rename it
    over path; return path. A failure removes the temporary file and raises. The file is readable like every other
    output (0666 less the umask; mkstemp alone makes it 0600)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp", dir=os.path.dirname(path) or ".")

    def fill() -> None:
        with os.fdopen(fd, mode) as fh:
            with contextlib.suppress(OSError):  # a filesystem without modes (some network mounts) keeps mkstemp's
                os.fchmod(fh.fileno(), 0o666 & ~UMASK)
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())

    return _publish(tmp, path, fill)


def write_atomic_named(path: str, tmp: str, write: Callable[[str], None]) -> str:
    """Like write_atomic for a writer that takes a file name: write(tmp) fills tmp (the caller names it beside
    path: torch.save stores the name in its archive, so the name keeps the bytes), which is fsynced and renamed
    over path; return path. A failure removes tmp and raises."""

    def fill() -> None:
        write(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)

    return _publish(tmp, path, fill)


def leftovers(path: str) -> list[str]:
    """The temporary files of write_atomic(path, ...) calls that were killed before they could remove them."""
    folder, name = os.path.split(path)
    return glob.glob(os.path.join(glob.escape(folder or "."), f".{glob.escape(name)}.*.tmp"))
