"""glibc heap settings for CPU runs: freed multi-MB tensors stay in the process for the next step to reuse.

torch's CPU allocator hands every tensor back to malloc. glibc serves blocks over its mmap threshold with
fresh mmap pages and unmaps them on free, so a training step that makes the same 16-32 MB activations each
step page-faults them in again every time. Raising the threshold to its 32 MiB maximum, with a large trim
threshold and top pad, keeps those blocks in the heap. Measured on one thread of a 2-core Xeon: the thesis
GAN's training step (G and D, batch 1024, the pools of ddfbench.models._stride1_pool) took 0.96 s a step
with glibc's defaults and 0.81-0.89 s with these (two runs each; issue 15's note gives the script).
Elsewhere (macOS, musl) nothing changes.
"""

from __future__ import annotations

import ctypes
import ctypes.util

MMAP_THRESHOLD_B = 32 * 2**20   # glibc's largest allowed M_MMAP_THRESHOLD on 64-bit
TRIM_THRESHOLD_B = 2**30        # free heap top kept before glibc returns it to the OS
TOP_PAD_B = 256 * 2**20         # extra bytes asked of the OS each time the heap grows
_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3  # <malloc.h>


def keep_freed_blocks() -> bool:
    """Set glibc's mmap/trim thresholds and top pad for this process; False where malloc is not glibc's."""
    name = ctypes.util.find_library("c")
    libc = ctypes.CDLL(name) if name else None
    if libc is None or not hasattr(libc, "mallopt") or not hasattr(libc, "gnu_get_libc_version"):
        return False
    return all(libc.mallopt(option, value) == 1 for option, value in (
        (_M_MMAP_THRESHOLD, MMAP_THRESHOLD_B), (_M_TRIM_THRESHOLD, TRIM_THRESHOLD_B), (_M_TOP_PAD, TOP_PAD_B)))
