"""Compiling the kernels ahead of use: in one process per core, in units, with progress.

numba compiles each generic loop once per (scene, method family), tableaus that are tuples (Gauss,
Euler, RK4: methods._fixed) once per length, and keeps it in its disk cache (kernels.cachestamp).
A *unit* is everything one (scene, family) pair needs: its loops for one trajectory and for
ensembles, its tangent maps, the scene's energies and vector field, the map product. The `common` unit holds what building a setup compiles (the charged scene's beta(t),
which its initial state needs). A compiled unit leaves a marker beside the cache, and so does a
complete cache, so a warm cache is recognised without loading or importing anything more.

`compile_all()` compiles the missing units in worker processes (`python -m cosymp.warm
--worker`), as many as there are cores, each filling the shared cache; `Compiler` does the same
in the background, in an order that can change while it runs (what a user asks for first), and
`ensure(setup)` waits, in the calling thread, for the unit a run needs while a background
compiler is active. A server started on a cold cache therefore loads every kernel from the
cache instead of compiling it itself, which would keep numba's compilation memory for good.
"""
import argparse
import dataclasses
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time

from .kernels import cachestamp

COMMON = "common"
COMPLETE = "complete"


@dataclasses.dataclass(frozen=True)
class Unit:
    """The kernels of one scene and one method family (or, with scene = None, the common unit)."""

    key: str
    scene: str = None
    methods: tuple = ()

    def describe(self):
        if self.scene is None:
            return "common kernels"
        family = self.key.split("/")[1]
        return f"{self.scene} × {family} ({', '.join(self.methods)})"

    def run(self):
        """Compile (or load from the cache) every kernel of the unit."""
        from .integrate import Setup
        from .scenes import SCENES

        if self.scene is None:
            for scene in SCENES.values():
                Setup.make(scene, next(iter(_families(scene).values()))[0])
            return
        from numba import typeof

        compiled = set()
        for name in self.methods:  # each data type of the family (tuples: one per length)
            setup = Setup.make(self.scene, name)
            if typeof(setup.data) not in compiled:
                compiled.add(typeof(setup.data))
                _exercise(setup)


def _families(scene):
    """{family name: the methods of that family that apply to the scene}, in registry order."""
    from .methods import METHODS

    out = {}
    for m in METHODS.values():
        if m.refusal(scene) is None:
            out.setdefault(type(m.data()).__name__, []).append(m.name)
    return out


def _exercise(setup):
    """A few steps through every compiled path a run of this setup can take."""
    from .diagnostics import nearby_states, tangent_maps
    from .drive import Drive, batch_runs, batchable
    from .integrate import simulate
    from .reference import scipy_reference
    from .summary import transport

    h = setup.scene.h
    m = 2 * setup.scene.ndof
    single = simulate(setup, h, 4 * h)
    ensemble = simulate(setup, h, 4 * h, z0=nearby_states(setup.start[0], 1e-4, m + 1), increments=True)
    tangent_maps(single, last=True)
    tangent_maps(ensemble)
    Drive(setup, h, growth=True).run(4)
    Drive(setup, h, z0=ensemble.z[0], width=2).run(4)
    if batchable(setup):
        batch_runs(setup, h, 4, [tuple(setup.P)], setup.start, growth=True)
    scipy_reference(setup, 2 * h)
    if setup.scene.has_gauges:
        transport(single, setup)


def key_of(setup):
    """The key of the unit that compiles what a run of `setup` needs."""
    return f"{setup.scene.name}/{type(setup.data).__name__}"


def unit_keys(scene, methods):
    """The keys of the units that runs of these methods on the scene (a name) need, with the
    common unit's (building a setup of some scenes compiles; nothing is compiled here)."""
    from .methods import METHODS

    return [COMMON] + list(dict.fromkeys(f"{scene}/{type(METHODS[m].data()).__name__}" for m in methods))


def run_keys(scene, methods, reference=True):
    """unit_keys of runs of these methods (names) on the scene (a Scene) and, with `reference`, of
    the reference they are measured against: the exact flow where the scene has one, else rk8."""
    return unit_keys(scene.name, [*methods, *(["exact" if scene.has_flow else "rk8"] if reference else [])])


def units():
    """The common unit, then one unit per (scene, family), in registry order."""
    from .scenes import SCENES

    return [Unit(COMMON)] + [Unit(f"{scene.name}/{family}", scene.name, tuple(names))
                             for scene in SCENES.values() for family, names in _families(scene).items()]


def _marker_dir():
    return os.path.join(cachestamp.cache_dir(), "cosymp-warm")


def _tag():
    """What a compiled unit is valid for: these sources, this numba, this machine."""
    import llvmlite.binding as llvm
    import numba

    return f"{cachestamp.package_stamp()[:24]}-{numba.__version__}-{platform.machine()}-{llvm.get_host_cpu_name()}"


def _marker(key):
    return os.path.join(_marker_dir(), f"{key.replace('/', '-')}.{_tag()}")


def is_warm():
    """Whether every unit is compiled (one file to look at, nothing to import)."""
    return os.path.exists(_marker(COMPLETE))


def missing():
    """The units whose kernels are not in the cache yet."""
    if is_warm():
        return []
    todo = [u for u in units() if not os.path.exists(_marker(u.key))]
    if not todo:
        _mark(COMPLETE, "every unit")
    return todo


def _mark(key, text):
    """Leave the marker of a compiled unit (and remove its markers of other sources)."""
    folder = _marker_dir()
    os.makedirs(folder, exist_ok=True)
    stale = key.replace("/", "-") + "."
    for name in os.listdir(folder):
        if name.startswith(stale):
            os.unlink(os.path.join(folder, name))
    with open(_marker(key), "w") as f:
        f.write(f"{text}\n")


class Compiler:
    """Compiles units in `processes` worker processes, in list order; `prioritize` moves units
    to the front, `wait` blocks until they are compiled (or failed), `join` until all are.

    report(text) receives one line per finished unit: how many of how many, the elapsed time,
    what was compiled and what is being compiled. nice lowers the workers' priority (a server
    compiling in the background stays responsive)."""

    def __init__(self, todo, processes=None, nice=0, report=None):
        self._todo = list(todo)
        self.total = len(self._todo)
        self.done = 0
        self.finished = not self._todo
        self.failed = {}
        self.started = time.perf_counter()
        self._events = {u.key: threading.Event() for u in self._todo}
        self._running = {}
        self._lock = threading.Lock()
        self._report = report or (lambda text: None)
        self._nice = nice
        width = max(1, min(processes or os.cpu_count() or 1, self.total))
        self._threads = [threading.Thread(target=self._feed, args=(i,), daemon=True, name=f"cosymp-compile-{i}")
                         for i in range(width)]
        if self.total:
            self._report(f"compiling {self.total} groups of kernels in {width} processes (cold cache), first: "
                         f"{', '.join(u.describe() for u in self._todo[:width])}")
        for t in self._threads:
            t.start()

    @property
    def processes(self):
        return len(self._threads)

    def _next(self, slot):
        with self._lock:
            if not self._todo:
                return None
            unit = self._todo.pop(0)
            self._running[slot] = unit
            return unit

    def _feed(self, slot):
        unit = self._next(slot)
        while unit is not None:
            with tempfile.TemporaryFile(mode="w+") as log, subprocess.Popen(
                    [sys.executable, "-m", "cosymp.warm", "--worker", "--nice", str(self._nice)],
                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True, bufsize=1) as worker:
                while unit is not None:
                    error = _compile_in(worker, log, unit.key)
                    self._finish(slot, unit, error)
                    unit = self._next(slot)
                    if error:
                        break
                worker.stdin.close()

    def _finish(self, slot, unit, error):
        with self._lock:
            self.done += 1
            del self._running[slot]
            if error:
                self.failed[unit.key] = error
            self.finished = self.done == self.total
            now = sorted(u.describe() for u in self._running.values())
            line = (f"[{self.done:3d}/{self.total}] {time.perf_counter() - self.started:6.1f} s  "
                    + (f"FAILED {unit.describe()}: {error}" if error else f"compiled {unit.describe()}")
                    + (f"; compiling {', '.join(now)}" if now else ""))
        self._events[unit.key].set()
        self._report(line)

    def prioritize(self, keys):
        """Move the units with these keys (still waiting) to the front, in the order given."""
        with self._lock:
            first = [u for k in keys for u in self._todo if u.key == k]
            self._todo = first + [u for u in self._todo if u not in first]

    def wait(self, keys, timeout=None):
        """Block until the units with these keys (those this compiler has) are compiled or failed."""
        keys = [k for k in keys if k in self._events]
        self.prioritize(keys)
        for k in keys:
            self._events[k].wait(timeout)

    def join(self):
        for t in self._threads:
            t.join()


def _compile_in(worker, log, key):
    """Have a worker process compile one unit: '' once done, else why it stopped."""
    try:
        worker.stdin.write(key + "\n")
        worker.stdin.flush()
        if worker.stdout.readline().rstrip("\n") == f"ok {key}":
            return ""
    except OSError:
        pass
    worker.wait()
    log.seek(0)
    tail = [line for line in log.read().splitlines() if line.strip()][-1:]
    return f"the compiling process stopped ({' '.join(tail) or f'exit code {worker.returncode}'})"


def compile_all(processes=None, report=None):
    """Compile the missing units in worker processes, one per core; returns the Compiler once
    every unit is done."""
    compiler = Compiler(missing(), processes, report=report)
    compiler.join()
    missing()
    return compiler


def compile_missing(keys, processes=None, report=None):
    """Compile the units with these keys that are not in the cache yet, in worker processes (one per
    core), reporting each; returns the Compiler once they are done, None if none was missing."""
    todo = [u for u in missing() if u.key in keys]
    if not todo:
        return None
    compiler = Compiler(todo, processes, report=report)
    compiler.join()
    return compiler


_background = None
_START = threading.Lock()


def start(first=(), processes=None, report=None):
    """Once per process: compile the missing units in lowered-priority worker processes while
    this process goes on, the units with the keys in `first` first and the common unit next; runs
    of a unit still being compiled wait for it (ensure). Returns the Compiler, or None when
    nothing was missing."""
    global _background
    with _START:
        if _background is None:
            todo = missing()
            ranked = [u for k in [*first, COMMON] for u in todo if u.key == k]
            _background = Compiler(ranked + [u for u in todo if u not in ranked], processes, nice=10, report=report)
    return None if _background.total == 0 else _background


def compiling():
    """Whether a background compiler is still at work: a run may then wait minutes (ensure)."""
    return _background is not None and not _background.finished


def ensure(setup):
    """Wait for the unit of this setup while a background compiler has it (a no-op otherwise)."""
    if compiling():
        _background.wait([key_of(setup)])


def _serve(nice):
    """The worker's loop: one unit key per line in, 'ok KEY' out once it is compiled. A unit that
    fails ends the process with its traceback on stderr, which the parent reports."""
    if nice:
        os.nice(nice)
    by_key = {u.key: u for u in units()}
    for line in sys.stdin:
        key = line.strip()
        by_key[key].run()
        _mark(key, by_key[key].describe())
        sys.stdout.write(f"ok {key}\n")
        sys.stdout.flush()


if __name__ == "__main__":
    p = argparse.ArgumentParser(prog="python -m cosymp.warm", description="a compiling worker of cosymp.warm.Compiler")
    p.add_argument("--worker", action="store_true", required=True)
    p.add_argument("--nice", type=int, default=0)
    _serve(p.parse_args().nice)
