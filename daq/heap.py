"""Give the C heap's freed memory back to the operating system (glibc only).

numpy's arrays come from the C allocator. glibc keeps what they free in its heap for reuse and
returns only the free top of each arena, so a process whose working set peaks now and then (an
impact's analysis, a first look) keeps the pages of every peak: its RSS ratchets up with each new
peak although the memory in use stays flat (``benchmarks/soak.py`` at 25.6 kHz: glibc held
285 -> 360 MB while 170-190 MB was in use). ``malloc_trim(0)`` hands every whole free page of
every arena back (``madvise``); it takes milliseconds. Elsewhere (macOS, musl, Windows) it is a
no-op that says so.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys


def _malloc_trim():
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc
        return None
    fn.argtypes, fn.restype = [ctypes.c_size_t], ctypes.c_int
    return fn


_TRIM = _malloc_trim()


def release_free_memory() -> bool:
    """Return the C heap's free pages to the OS; False where the C library cannot (not glibc)."""
    if _TRIM is None:
        return False
    _TRIM(0)
    return True
