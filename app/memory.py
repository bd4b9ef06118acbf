"""Memory: what one server's computations may hold, and freed memory given back to the system.

Budget. Every computation leases its peak memory from one budget per server process before it
starts, and holds it while its result is shown (or, for a measurement, while it runs); a lease
that would pass the cap (COSYMP_MEMORY_CAP_MB, default 4096) is refused with a message saying
what to change, and the last results stay. Closed pages give their leases back.

Allocator. With glibc's defaults a server that has shown a large result keeps its memory after
the page is closed: glibc raises its mmap threshold to the largest block freed so far (up to
32 MiB) and serves later large arrays from its heaps, and each thread that allocated keeps its
own heap, trimmed only from the top. The load test measured 250-515 MB of such free-but-kept
memory after every page had been closed. `map_large_blocks()` fixes the mmap threshold at 1 MiB
(as MALLOC_MMAP_THRESHOLD_=1048576 would): every array of 1 MiB or more is mapped on its own
and unmapped when freed. `give_back()` returns the free pages of every heap (malloc_trim). Both
do nothing where the C library is not glibc.

Collector. Python's cycle collector runs a full collection, over every tracked object of the
process, when enough objects have survived younger collections, inside whatever code allocates the
last one: here, a page's handler building a tab or a plot. With a few pages open each took
95-350 ms (it grows with the sessions alive) and came in the middle of a click. `Collector`
takes full collections off that path: a task on the server's loop runs them between handlers,
once the server is idle, or after enough younger collections in any case (a closed page's
session is a web of reference cycles that only a full collection frees). A page that stops asks
for one at the next idle moment (`Collector.request`): an idle server makes few younger
collections, so a closed page's state could otherwise wait indefinitely.
"""
import asyncio
import ctypes
import gc
import logging
import os
import threading
import time
import weakref
from functools import cache

from cosymp.errors import InputError

MB = 1 << 20


class MemoryBudget:
    """Bytes leased by the computations of all sessions, and the cap they may not pass."""

    def __init__(self, cap_bytes):
        self.cap = cap_bytes
        self.used = 0
        self._lock = threading.Lock()

    def lease(self, nbytes, what):
        """A Lease of nbytes, or InputError saying what to change when the cap would be passed."""
        with self._lock:
            if nbytes > self.cap:
                raise InputError(f"{what} needs about {nbytes / MB:.0f} MB, more than this server's cap of "
                                 f"{self.cap / MB:.0f} MB (COSYMP_MEMORY_CAP_MB): increase h or shorten T")
            if self.used + nbytes > self.cap:
                raise InputError(f"{what} needs about {nbytes / MB:.0f} MB and only "
                                 f"{(self.cap - self.used) / MB:.0f} MB of this server's "
                                 f"{self.cap / MB:.0f} MB are free while other runs hold the rest: "
                                 "try again in a moment, or increase h or shorten T")
            self.used += nbytes
        return Lease(self, nbytes)

    def fits(self, nbytes):
        """Whether a lease of nbytes would be granted now."""
        with self._lock:
            return self.used + nbytes <= self.cap

    def _give_back(self, nbytes):
        with self._lock:
            self.used -= nbytes


class Lease:
    """Memory held from a MemoryBudget until released (releasing twice is harmless)."""

    def __init__(self, budget, nbytes):
        self._budget = budget
        self.nbytes = nbytes

    def release(self):
        if self.nbytes:
            self._budget._give_back(self.nbytes)
            self.nbytes = 0


BUDGET = MemoryBudget(int(float(os.environ.get("COSYMP_MEMORY_CAP_MB", "4096")) * MB))

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


COLLECT_CHECK_S = 0.25  # how often the collector's task looks
COLLECT_IDLE_S = 2.0  # a full collection waits for the server to be idle this long...
COLLECT_DUE = 10  # ...once this many generation-1 collections came after the last full one (Python's own threshold)
COLLECT_FORCED = 200  # and runs at the next look, idle or not, after this many
COLLECT_FOLLOW_S = (5.0, 15.0, 40.0)  # after a requested one, more at these delays (each once idle)
NEVER = 1 << 30


class Collector:
    """Full garbage collections on the server's loop, between handlers (see the module's doc)."""

    task = None
    requested = False
    follow = ()  # the times (time.monotonic) of the follow-up collections still due

    @classmethod
    def request(cls):
        """A full collection at the next idle moment, however few younger collections came since the
        last, and more COLLECT_FOLLOW_S after it: a page has stopped, and its state is garbage only a
        full collection frees, some of it only once what still refers to it has let go (a run's
        thread ending after its chunk, a timer firing, a task finishing). The load test saw 10 of
        11 closed pages freed in 60 s, in two CI runs: in the second, a collection 1.6 s after the
        sessions ended freed eight pages' state, one 7.4 s later two more, and none came after it
        (an idle server makes no younger collections). Not reproduced alone (five runs)."""
        cls.requested = True

    @classmethod
    def start(cls, idle):
        """Turn Python's automatic full collections off and run them from a task instead: when
        idle(COLLECT_IDLE_S) says the server's pages have been idle that long, or when they are
        overdue. Once per process, on the server's running loop (without one, nothing changes)."""
        if cls.task is not None:
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return
        gen0, gen1, _ = gc.get_threshold()
        gc.set_threshold(gen0, gen1, NEVER)
        cls.task = loop.create_task(cls._run(idle))

    @staticmethod
    async def _run(idle):
        while True:
            await asyncio.sleep(COLLECT_CHECK_S)
            younger = gc.get_count()[2]  # generation-1 collections since the last full one
            now = time.monotonic()
            followed = bool(Collector.follow) and now >= Collector.follow[0]
            due = younger >= COLLECT_DUE or Collector.requested or followed
            if younger >= COLLECT_FORCED or (due and idle(COLLECT_IDLE_S)):
                if Collector.requested:
                    Collector.follow = tuple(now + s for s in COLLECT_FOLLOW_S)
                Collector.follow = tuple(t for t in Collector.follow if t > now)
                Collector.requested = False
                gc.collect()


# Logged (under Panel's logger: PANEL_LOG_LEVEL=info shows it beside Panel's session lines) when
# a page's App is garbage-collected, so an operator (and the load test) can see closed pages freed.
LOG = logging.getLogger("panel.cosymp")
FREED = "cosymp: a page's state was freed"


def log_when_freed(app):
    """Log FREED once `app` has been garbage-collected and its memory given back to the system.
    Its objects are freed after the collection's finalizers (this is one), so that happens in a
    callback on the server's event loop once the collection is over (without a loop, at once).
    (Not in the app's script: Panel clears a session's script globals when the session ends.)"""
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:
        loop = None
    weakref.finalize(app, _freed, loop)


def _freed(loop):
    if loop is not None:
        try:
            loop.call_soon_threadsafe(_give_back_freed)
            return
        except RuntimeError:  # the loop has closed: the server is stopping
            pass
    _give_back_freed()


def _give_back_freed():
    give_back()
    LOG.info(FREED)
