"""ramdaq.daq.heap: the C heap's free pages go back to the OS."""

import ctypes
import ctypes.util
import sys

import psutil
import pytest

from ramdaq.daq.heap import release_free_memory


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc_trim")
def test_free_pages_in_the_middle_of_the_heap_go_back():
    """128 MB in 64 kB blocks (below glibc's mmap threshold: they live in the heap), all freed
    but the last, which pins the heap's top so that free() alone returns nothing. RSS drops by
    at least half of it after the trim (the rest is margin for whatever else moved)."""
    libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    n, size = 2048, 64 * 1024
    blocks = [libc.malloc(size) for _ in range(n)]
    for b in blocks:
        ctypes.memset(b, 1, size)  # touched: resident
    for b in blocks[:-1]:
        libc.free(b)
    before = psutil.Process().memory_info().rss
    assert release_free_memory()
    after = psutil.Process().memory_info().rss
    libc.free(blocks[-1])
    assert before - after >= n * size / 2


_LARGE_BLOCK_CHILD = """
import numpy as np, psutil
from ramdaq.daq.heap import map_large_blocks
assert map_large_blocks()
a = np.ones(30 << 17); del a       # freed 30 MB: glibc alone would raise its threshold to it
b = np.ones(16 << 17)              # 16 MB, touched
pin = np.ones(1000)                # a small block after it
before = psutil.Process().memory_info().rss
del b
print(before - psutil.Process().memory_info().rss)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_a_large_array_freed_goes_back_at_once():
    """With map_large_blocks a 16 MB array freed after a 30 MB one (which would have raised
    glibc's dynamic threshold above it, so it would come from the heap and stay) goes back to
    the OS at once: RSS drops by at least 12 of its 16 MB (the rest is margin). In a child
    process: the setting is process-wide."""
    import subprocess

    out = subprocess.run([sys.executable, "-c", _LARGE_BLOCK_CHILD], capture_output=True, text=True,
                         check=True)
    assert int(out.stdout.strip()) >= 12 << 20, out.stdout
