"""Freed memory back to the system, so that a long-lived server's size follows what its pages hold.

With glibc's defaults a server that has shown a large result keeps its memory after the page is
closed: glibc raises its mmap threshold to the largest block freed so far (up to 32 MiB) and
serves later large arrays from its heaps, and each thread that allocated keeps its own heap
(arena), trimmed only from the top. The load test measured 250-515 MB of such free-but-kept
memory after every page had been closed and garbage-collected.

`map_large_blocks()` fixes the mmap threshold at 1 MiB (as MALLOC_MMAP_THRESHOLD_=1048576 in the
environment would): every array of 1 MiB or more is mapped on its own and unmapped when freed.
`give_back()` returns the free pages of every heap (malloc_trim). Both do nothing where the C
library is not glibc.
"""
import ctypes
from functools import cache

M_MMAP_THRESHOLD = -3  # mallopt's parameter number in glibc's malloc.h
MMAP_THRESHOLD = 1 << 20


@cache
def _glibc():
    try:
        libc = ctypes.CDLL(None)
    except (OSError, TypeError):  # Windows has no process-wide C namespace to open
        return None
    if not (hasattr(libc, "malloc_trim") and hasattr(libc, "mallopt")):
        return None
    libc.malloc_trim.argtypes, libc.malloc_trim.restype = [ctypes.c_size_t], ctypes.c_int
    libc.mallopt.argtypes, libc.mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return libc


@cache
def map_large_blocks():
    """Fix glibc's mmap threshold at MMAP_THRESHOLD (once per process)."""
    libc = _glibc()
    if libc is not None:
        libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)


def give_back():
    """Return the free pages of every heap to the system (a few ms; about 0.1 s per GB returned)."""
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)
