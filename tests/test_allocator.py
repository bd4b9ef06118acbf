"""app/memory.py: freed memory goes back to the system.

The pattern of a server thread: it frees a large array (glibc then raises its mmap threshold to
that size), allocates 100 arrays of 2 MiB with small blocks kept in between, and frees the
arrays. Each case runs in a fresh process (the threshold is process-wide) without the MALLOC_*
and GLIBC_TUNABLES environment that would tune glibc, from the RSS before the thread to the RSS
after the arrays were freed. The first case is glibc's behaviour, the reason for the module.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from app import memory as allocator

pytestmark = pytest.mark.skipif(allocator._glibc() is None, reason="the C library is not glibc")

PROBE = """
import json, sys, threading
import numpy as np
from app import memory as allocator

def rss_mb():
    with open("/proc/self/status") as f:
        return int(f.read().split("VmRSS:")[1].split()[0]) / 1024

mode = sys.argv[1]
if mode == "map_large_blocks":
    allocator.map_large_blocks()
kept_small = []

def work(out):
    big = np.ones(16 << 17)
    del big
    arrays = []
    for _ in range(100):
        arrays.append(np.ones(1 << 18))
        kept_small.append(np.ones(8))
    out.append(arrays)

out = []
before = rss_mb()
thread = threading.Thread(target=work, args=(out,))
thread.start()
thread.join()
held = rss_mb() - before
out.clear()
freed = rss_mb() - before
if mode == "give_back":
    allocator.give_back()
print(json.dumps({"held": held, "after_free": freed, "after": rss_mb() - before}))
"""


def probe(mode):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("MALLOC_", "GLIBC_TUNABLES"))}
    done = subprocess.run([sys.executable, "-c", PROBE, mode], check=False, capture_output=True, text=True, timeout=120,
                          cwd=Path(allocator.__file__).resolve().parents[1], env=env)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_by_default_glibc_keeps_a_threads_freed_arrays():
    r = probe("default")
    assert r["held"] > 150 and r["after"] > 150, r


def test_map_large_blocks_unmaps_them_when_freed():
    r = probe("map_large_blocks")
    assert r["held"] > 150 and r["after_free"] < 20, r


def test_give_back_returns_them():
    r = probe("give_back")
    assert r["held"] > 150 and r["after_free"] > 150 and r["after"] < 20, r
