"""One background-job mechanism for every feature: computations off the event loop.

A `Job` computes in a thread of its own. Requests made while it computes are merged into one
more computation with the latest inputs (`request`); a measurement started by a button starts
only when none is running (`start`). Each computation leases its peak memory from the server's
budget before it starts (memory.BUDGET) and gives it back when it ends, or, for a live view's
result (HOLD), when a newer result replaces it. It publishes its progress (fraction and label)
and partial results (a long run's envelopes) to the event loop as they come, can be cancelled
(at its next progress report), and after `release()` (the page was closed) it stops and nothing
more is published: drawn for a destroyed document, a result would keep the whole session alive.
A deterministic computation (a map, a long run) is remembered by the server for every page
(`Job.KEEP`, `REMEMBERED`): asked for again, by this page or another, it is shown at once.

Under `panel serve` the loop side runs as a task on the session's event loop (param's async
executor); without a server the same code runs to completion before the call returns, so the
states are testable in a plain Python session.
"""
import asyncio
import dataclasses
import datetime
import functools
import math
import threading
import time

import param

from cosymp import warm
from cosymp.errors import InputError, RunError

from . import memory

PROGRESS_S = 0.25  # progress reaches the page at most this often
# Quick results (Job.quick) reach the page at most this often: a burst of changes (a slider moved by
# the arrow keys) asked for one each, and the page drew them one after the other, about 50 ms apiece.
QUICK_GAP_S = 0.1
# (KIND, key of the inputs) -> (result, datetime computed) of the deterministic computations of any
# page of this server (Job.KEEP): a class opening the same tab computes it once, not once per student.
REMEMBERED = {}

# What a computation may raise besides cosymp's own errors (InputError is a ValueError, RunError a
# RuntimeError): each becomes a message and the session goes on.
FAILURES = (ArithmeticError, AttributeError, LookupError, MemoryError, OSError, RuntimeError, TypeError,
            ValueError)


@dataclasses.dataclass(frozen=True)
class Note:
    """A message for the user: level is 'error', 'warning' or 'info'."""

    level: str
    text: str


class Cancelled(Exception):
    """Raised from a progress report to stop a computation that was cancelled."""


def failure_text(err):
    """A user-facing text for an exception: cosymp's own messages as they are, others with their type."""
    return str(err) if isinstance(err, (InputError, RunError)) else f"{type(err).__name__}: {err}"


class Run:
    """One computation in its thread: what it reports to the loop, and whether it was cancelled."""

    def __init__(self, job, inputs, lease):
        self.inputs = inputs
        self.lease = lease
        self.cancelled = False
        self.discarded = False  # what it still publishes is dropped (Job.discard)
        self.latest = (0, 1, "starting")
        self.partial = None
        self.result = None
        self.error = None
        self.started = time.perf_counter()
        self.computed_s = None  # how long the computation itself took, in its thread
        self.threaded = False  # computed in its own thread (`wait`), not in the handler (`Job._now`)
        self.finished = threading.Event()
        self._wake = None
        self._compute = job._compute
        self.thread = threading.Thread(target=self._main, daemon=True, name=f"cosymp-{job.KIND}")

    def report(self, done, total, label=""):
        """Progress from the computation (any thread); raises Cancelled once the run is cancelled."""
        if self.cancelled:
            raise Cancelled
        self.latest = (done, total, label)
        self._signal()

    def publish(self, partial):
        """A partial result for the loop (the latest one wins)."""
        self.partial = partial
        self._signal()

    def _signal(self):
        if self._wake is not None:
            try:
                self._wake()
            except RuntimeError:  # the loop is closed: the server is stopping
                pass

    def _main(self):
        start = time.perf_counter()
        try:
            self.result = self._compute(self.inputs, self)
        except Cancelled:
            self.cancelled = True
        except FAILURES as err:
            self.error = err
        finally:
            self.computed_s = time.perf_counter() - start
            if self.result is None and self.error is None and not self.cancelled:
                self.error = RuntimeError("the computation stopped without a result (see the server's log)")
            self.finished.set()
            self._signal()

    async def wait(self, on_progress, on_partial, interval=0.0):
        """Start the thread and relay its reports on this loop until it ends: the latest progress
        report at most once per PROGRESS_S seconds (each one costs the page a layout of the whole
        document: a sweep reporting every cell froze the browser), and the latest partial result
        at most once per `interval` seconds (and the last of each at the end)."""
        loop = asyncio.get_running_loop()
        woken = asyncio.Event()
        self._wake = lambda: loop.call_soon_threadsafe(woken.set)
        self.threaded = True
        self.thread.start()
        shown, drawn, told = None, -math.inf, -math.inf
        while True:
            now = time.perf_counter()
            waits = [max(0.0, drawn + interval - now)] if self.partial is not None else []
            if self.latest != shown:
                waits.append(max(0.0, told + PROGRESS_S - now))
            try:
                await asyncio.wait_for(woken.wait(), min(waits, default=None))
            except TimeoutError:
                pass
            woken.clear()
            ended = self.finished.is_set()  # read first: what was reported before the end is read below
            if self.latest != shown and (ended or time.perf_counter() >= told + PROGRESS_S):
                shown = self.latest
                if not self.discarded:
                    on_progress(*shown)
                told = time.perf_counter()
            if self.partial is not None and (ended or time.perf_counter() >= drawn + interval):
                partial, self.partial = self.partial, None
                if not self.discarded:
                    on_partial(self.inputs, partial)
                drawn = time.perf_counter()
            if ended:
                return


class Job(param.Parameterized):
    """A computation of a feature (see the module's doc). Subclasses give `_inputs()` (the
    validated inputs, None for nothing to do, or InputError), `_bytes(inputs)` (the memory it
    leases), `_compute(inputs, run)` (pure, in its thread; `run.report(done, total, label)` and
    `run.publish(partial)`), `_finish(inputs, result)` and optionally `_partial(inputs, part)`
    (on the loop), and `say(note)`."""

    running = param.Boolean(default=False, doc="A computation is under way.")
    progress = param.Number(default=0.0, bounds=(0.0, 1.0), doc="Fraction of the current computation done.")
    label = param.String(default="", doc="What the computation is doing now.")
    status = param.String(default="", doc="How the last computation ended.")

    KIND = "computation"
    WHAT = "this computation"
    PREFIX = ""  # put before a message about refused inputs
    HOLD = False  # hold the lease while the result is shown (a live view), not only while computing
    KEEP = 0  # how many of its results of distinct inputs (`_key`) the server remembers for every page

    def __init__(self, **params):
        super().__init__(**params)
        self._wanted = 0
        self._done = 0
        self._closed = False
        self._held = None
        self._last_quick = -math.inf
        self.run = None

    # ---- requests

    def request(self):
        """Compute from the current inputs, after the computation under way (the latest wins); at once,
        in this thread, when none is under way and this one is quick (`quick()`)."""
        self._wanted += 1
        if self.running or self._closed:
            return
        quick = not warm.compiling() and self.quick()
        wait = self._last_quick + QUICK_GAP_S - time.perf_counter()
        if quick and wait <= 0:
            self._last_quick = time.perf_counter()
            self._now()
        else:
            self.running = True
            param.parameterized.async_executor(functools.partial(self._drain, wait if quick else 0.0))

    def quick(self):
        """Whether the computation the inputs ask for is expected to take so little (a few tens of ms)
        that it runs in the handler of the change that asked for it: its results then reach the page
        in the same message as the change's other effects, and the page is laid out once, not twice.
        A remembered result is quick."""
        if not self.KEEP:
            return False
        try:
            return self._remembered(self._inputs()) is not None
        except InputError:
            return False

    def _remembered(self, inputs):
        """The remembered (result, when) of these inputs, or None."""
        key = self._key(inputs) if self.KEEP and inputs is not None else None
        return None if key is None else REMEMBERED.get((self.KIND, key))

    def remembers_ahead(self):
        """Whether the server remembers results of this job for every page (KEEP) and none of its
        current inputs yet, and the memory the computation leases is free now."""
        if not self.KEEP:
            return False
        try:
            inputs = self._inputs()
            return inputs is not None and self._remembered(inputs) is None and memory.BUDGET.fits(self._bytes(inputs))
        except InputError:
            return False

    def remember_ahead(self):
        """Compute, in its thread, the result of the current inputs that the server remembers for
        every page, where `remembers_ahead` and nothing runs (a spare session's idle time:
        main.App._remember_ahead). Returns whether it started."""
        if self.running or self._closed or not self.remembers_ahead():
            return False
        self.request()
        return True

    def start(self):
        """Start a computation unless one is running (a button's action)."""
        if not self.running:
            self.request()

    def cancel(self):
        """Stop the computation under way at its next progress report (and what was asked for after
        it); a request made after this runs once that computation has stopped."""
        self._done = self._wanted = max(self._done, self._wanted)
        if self.run is not None:
            self.run.cancelled = True

    def discard(self):
        """Stop the computation under way and drop what it still publishes (its inputs no longer
        apply: another scene)."""
        self.cancel()
        if self.run is not None:
            self.run.discarded = True

    @property
    def busy(self):
        """A computation is under way that is not being stopped."""
        return self.running and not (self.run is not None and self.run.cancelled)

    def release(self):
        """The page is gone: stop, give back the memory, publish nothing more."""
        self._closed = True
        self.cancel()
        if self._held is not None:
            self._held.release()

    def let_go(self):
        """The result shown (HOLD) is no longer shown: its memory goes back, and the last run lets it go."""
        if self._held is not None:
            self._held.release()
            self._held = None
        if self.run is not None and self.run.finished.is_set():
            self.run.result = None

    def refresh(self):
        """Compute from the current inputs now, in this thread (a page's first results). While the
        server still compiles kernels (a cold cache), the inputs are checked and the memory leased
        now, and the computation runs in its thread: one that waited here for its kernels held the
        whole server (every page, even /liveness) for minutes."""
        self._wanted += 1
        self._now()

    def _now(self):
        target = self._wanted
        run = self._begin()
        if run is not None and warm.compiling():
            self.running = True
            param.parameterized.async_executor(functools.partial(self._drain, begun=(run, target)))
            return
        if run is not None:
            run._main()
            self._end(run)
        self._done = max(self._done, target)

    def join(self, timeout=None):
        """Wait for the thread of the last computation (True once it has ended)."""
        return self.run is None or self.run.finished.wait(timeout)

    # ---- the loop side

    async def _drain(self, wait=0.0, begun=None):
        try:
            if begun is not None:  # a run begun in the handler (`_now`), and the request it meets
                run, target = begun
                await run.wait(self._on_progress, self._on_partial, self.partial_interval)
                self._end(run)
                self._done = max(self._done, target)
            if wait > 0:  # quick results came moments ago: changes made meanwhile are merged into one
                await asyncio.sleep(wait)
            while self._done < self._wanted and not self._closed:
                target = self._wanted
                run = self._begin()
                if run is not None:
                    await run.wait(self._on_progress, self._on_partial, self.partial_interval)
                    self._end(run)
                self._done = max(self._done, target)
        finally:
            self.running = False

    def _begin(self):
        try:
            inputs = self._inputs()
            if inputs is None:
                return None
            kept = self._remembered(inputs)
            if kept is not None:
                self._recalled(inputs, *kept)
                return None
            lease = memory.BUDGET.lease(self._bytes(inputs), self.WHAT)
        except InputError as err:
            self.say(Note("error", self.PREFIX + str(err)))
            self._refused()
            return None
        self.run = Run(self, inputs, lease)
        self.param.update(progress=0.0, label="starting")
        self._started(inputs)
        return self.run

    def _on_progress(self, done, total, label):
        if not self._closed:
            self.param.update(progress=min(1.0, done / max(total, 1)), label=label)

    def _on_partial(self, inputs, part):
        if not self._closed:
            self._partial(inputs, part)

    def _end(self, run):
        elapsed = time.perf_counter() - run.started
        if self._closed or run.cancelled or run.error is not None or not self.HOLD:
            run.lease.release()
        if self._closed:
            # The page stopped while this ran, and the full collection it asked for may have come
            # before the thread let go of the page's state: ask for another.
            memory.Collector.request()
            return
        if run.cancelled:
            self._cancelled(run.inputs, elapsed)
        elif run.error is not None:
            text = failure_text(run.error)
            self.status = f"failed after {elapsed:.1f} s: {text}"
            self.say(Note("error", f"{self.KIND} failed: {text}"))
            self._failed(run.inputs)
        else:
            if self.HOLD:
                previous, self._held = self._held, run.lease
                if previous is not None:
                    previous.release()
            self._finish(run.inputs, run.result)
            self._done_in(run.inputs, elapsed)
            self._remember(run)
        if not self.HOLD:
            memory.give_back()

    def _remember(self, run):
        key = self._key(run.inputs) if self.KEEP else None
        if key is None:
            return
        REMEMBERED.pop((self.KIND, key), None)  # the newest last
        REMEMBERED[(self.KIND, key)] = (self._kept(run), datetime.datetime.now())
        for old in [k for k in REMEMBERED if k[0] == self.KIND][:-self.KEEP]:
            del REMEMBERED[old]

    # ---- what subclasses may adjust

    def _key(self, inputs):
        """A hashable key of inputs whose result is remembered (KEEP), or None: the same key must
        mean the same result."""

    def _kept(self, run):
        """What is remembered of a completed run (`_recalled` gets it back)."""
        return run.result

    def _recalled(self, inputs, kept, when):
        """Show a remembered result instead of computing it again."""
        self._finish(inputs, kept)
        self.param.update(progress=1.0, label="done", status=f"computed at {when:%H:%M:%S} by this server "
                                                            "(the same inputs give the same result)")

    partial_interval = 0.0  # partial results are drawn at most once per this many seconds

    def _refused(self):
        """Called when the inputs were refused (the message is said)."""

    def _failed(self, inputs):
        """Called on the loop when the computation of these inputs failed (the message is said)."""

    def _started(self, inputs):
        """Called on the loop when a computation starts."""

    def _cancelled(self, inputs, elapsed):
        self.status = f"cancelled after {elapsed:.1f} s ({self.label})"

    def _done_in(self, inputs, elapsed):
        self.param.update(progress=1.0, label="done", status=f"done in {elapsed:.1f} s")

    def _partial(self, inputs, part):
        """A partial result, on the loop."""

    def _inputs(self):
        raise NotImplementedError

    def _bytes(self, inputs):
        raise NotImplementedError

    def _compute(self, inputs, run):
        raise NotImplementedError

    def _finish(self, inputs, result):
        raise NotImplementedError

    def say(self, note):
        raise NotImplementedError
