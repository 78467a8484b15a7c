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
