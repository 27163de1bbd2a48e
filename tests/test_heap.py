"""ddfbench.core.heap keeps freed multi-MB blocks in the heap: a 24 MiB tensor is not mmapped after the call."""

import os
import platform
import subprocess
import sys

import pytest

_SCRIPT = """
import ctypes, sys, torch
from ddfbench.core.heap import keep_freed_blocks
class Info(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in
                "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]
libc = ctypes.CDLL(None)
libc.mallinfo2.restype = Info
if sys.argv[1] == "keep":
    assert keep_freed_blocks()
before = libc.mallinfo2().hblkhd
t = torch.ones(6 * 2**20)  # 24 MiB
mapped = libc.mallinfo2().hblkhd - before
del t
print(mapped, libc.mallinfo2().fordblks)
"""


def _glibc_233() -> bool:
    name, version = platform.libc_ver()
    return name == "glibc" and tuple(int(v) for v in version.split(".")[:2]) >= (2, 33)  # mallinfo2


def _mapped_and_free(mode: str) -> tuple[int, int]:
    env = {k: v for k, v in os.environ.items()
           if not (k.startswith("MALLOC_") or k in ("GLIBC_TUNABLES", "LD_PRELOAD"))}  # glibc's own defaults
    out = subprocess.run([sys.executable, "-c", _SCRIPT, mode], capture_output=True,
                         text=True, check=True, env=env)
    mapped, free = out.stdout.split()
    return int(mapped), int(free)


@pytest.mark.skipif(not _glibc_233(), reason="glibc >= 2.33: mallopt and mallinfo2")
def test_big_tensor_stays_in_heap():
    mapped_default, _ = _mapped_and_free("default")
    mapped_kept, free_kept = _mapped_and_free("keep")
    assert mapped_default >= 24 * 2**20          # glibc's default at first: its own mmap, unmapped on free
    assert mapped_kept < 2**20                   # kept: from the heap...
    assert free_kept >= 24 * 2**20               # ...and still there, free, for the next step
