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
import sys


def _glibc(name: str, argtypes: list, restype: type):
    """glibc's function ``name`` through ctypes, or None off Linux or without glibc."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        # dlopen(NULL): the symbols the process has loaded, the C library's among them (no
        # ctypes.util.find_library, which runs ldconfig: ~30 ms wall at every import)
        fn = getattr(ctypes.CDLL(None), name)
    except (OSError, AttributeError):  # not glibc
        return None
    fn.argtypes, fn.restype = argtypes, restype
    return fn


_TRIM = _glibc("malloc_trim", [ctypes.c_size_t], ctypes.c_int)

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
"""glibc's ``mallopt`` parameter numbers of the trim and mmap thresholds (malloc.h)."""

_MALLOPT = _glibc("mallopt", [ctypes.c_int, ctypes.c_int], ctypes.c_int)


def release_free_memory() -> bool:
    """Return the C heap's free pages to the OS; False where the C library cannot (not glibc)."""
    if _TRIM is None:
        return False
    _TRIM(0)
    return True


def map_large_blocks(threshold_bytes: int = 4 << 20, keep_bytes: int = 64 << 20) -> bool:
    """Serve every allocation of ``threshold_bytes`` or more from its own mapping, returned to
    the OS the moment it is freed, and let the heap keep up to ``keep_bytes`` free at its top
    before trimming it; False where the C library cannot (not glibc).

    glibc starts with a 128 kB threshold but raises it to the size of each large block freed
    (up to 32 MB), after which blocks that size come from the heap and stay there when freed:
    a process that makes and drops arrays of tens of MB (``ramdaq gap``: Jacobians, dense unit
    responses, replicates) keeps the pages of its largest moment and grows by fragmentation
    beyond it. Setting the threshold fixes it, but also fixes the trim threshold at its 128 kB
    default (glibc otherwise keeps it at twice the mmap threshold): the heap's top is then
    given back and faulted in again at every turn of a loop (``ramdaq gap`` on 6 blows: 8.9 ->
    10.5 s CPU), hence ``keep_bytes``. On the 10-minute, 20-blow trial: 640-650 MB max RSS
    with this, 700 MB without; CPU unchanged within the noise (6 blows: 8.86 against 8.9 s)."""
    if _MALLOPT is None:
        return False
    return bool(_MALLOPT(_M_MMAP_THRESHOLD, int(threshold_bytes))
                and _MALLOPT(_M_TRIM_THRESHOLD, int(keep_bytes)))
