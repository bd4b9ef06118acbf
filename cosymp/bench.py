"""`cosymp bench`: ns/step of the numba core next to the same algorithm in plain C -O3.

The C reference (benchmarks/bench_ref.c, in cosymp's source checkout, not in the installed
package) mirrors cosymp/kernels and a representative subset of scenes and families formula for
formula; it is compiled here with gcc once per scene, so the ratio numba/C measures the compiled
code, not the algorithm. Which scenes it mirrors, and the parameters it reads, are read from its
source (its `#if SCENE == NAME` blocks and their Params structs); which families, from each
family's registration (kernels.registry: `mirror`). The other pairs get numba figures only, and
the table says which. Both run the same scene, method, h, initial state and number of steps, recording
every step, interleaved, and their final states must agree. On linear scenes both sides step
by the step's matrix (cosymp's ensemble path); `simulate` runs a single trajectory by member
steps instead, which cost less, or about as much for Gauss (kernels.loops.propagate_one).
"""
import ctypes
import json
import math
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from .errors import CosympError, InputError
from .integrate import MAX_RECORDED, Setup, get_scene, initial_states
from .kernels.families import NEWTON, OK, OVERFLOW, SINGULAR
from .kernels.loops import energies, propagate_matrix, propagate_one
from .kernels.registry import family
from .methods import METHODS
from .methods import method as get_method
from .progress import shown
from .scenes import SCENES

CC = "gcc"
CFLAGS = ("-O3", "-march=native", "-ffp-contract=fast", "-fno-math-errno", "-fPIC", "-shared")
TARGET = 1.2
BUDGET_S = 0.3
MIN_REPEATS = 3
AGREE = 1e-9
NO_H = np.empty((0, 1))  # the loops' records of H: none
STOPPED = {OVERFLOW: "overflow", NEWTON: "Newton did not converge", SINGULAR: "singular Newton matrix"}
C_SOURCE = Path(__file__).resolve().parent.parent / "benchmarks" / "bench_ref.c"
_C_SCENE = re.compile(r"^#(?:el)?if SCENE == (\w+)\s*\ntypedef struct \{ double ([\w, ]+); \} Params;", re.MULTILINE)


class _Loop(ctypes.Structure):
    """bench_ref.c's Loop: propagate's arguments; done receives the steps completed."""

    _fields_ = [("t0", ctypes.c_double), ("h", ctypes.c_double), ("Z", ctypes.c_void_p),
                ("PT", ctypes.c_void_p), ("N", ctypes.c_long), ("m", ctypes.c_long),
                ("nsteps", ctypes.c_long), ("stride", ctypes.c_long), ("Trec", ctypes.c_void_p),
                ("Zrec", ctypes.c_void_p), ("PTrec", ctypes.c_void_p), ("dZrec", ctypes.c_void_p),
                ("ndz", ctypes.c_long), ("done", ctypes.c_long)]


def _f64(values):
    return np.array(values, dtype=np.float64).ravel()


def mirrored_scenes(source=C_SOURCE):
    """{scene name: the fields of its parameter tuple the C mirror reads, in its struct's order}
    for every scene the C source mirrors."""
    return {name.lower(): tuple(f.strip() for f in fields.split(","))
            for name, fields in _C_SCENE.findall(Path(source).read_text())}


def _c_arg(v):
    """A ctypes argument: an array by address, an int as long, a float as double."""
    if isinstance(v, np.ndarray):
        return ctypes.c_void_p(v.ctypes.data)
    if isinstance(v, int):
        return ctypes.c_long(v)
    return ctypes.c_double(v)


def _compile(scene, workdir):
    """bench_ref.c built for one scene into a shared library in workdir, loaded."""
    k = scene.kernel
    lib = Path(workdir) / f"bench_{scene.name}.so"
    macros = {"SCENE": scene.name.upper(), "NDOF": k.ndof, "NCOEF": k.ncoef, "LINEAR": int(k.linear)}
    cmd = [CC, *CFLAGS, *(f"-D{key}={v}" for key, v in macros.items()), "-o", str(lib), str(C_SOURCE), "-lm"]
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        raise CosympError(f"compiling the C reference for '{scene.name}' failed: "
                          f"{' '.join(res.stderr.strip().splitlines()[-1:])}")
    return ctypes.CDLL(str(lib))


class _Runner:
    """One implementation of one (scene, method) pair: its own state and records, one timed call."""

    def __init__(self, z0, pt0, nsteps):
        self.z0, self.pt0, self.nsteps = z0, pt0, nsteps
        N, m = z0.shape
        self.Z = z0.copy()
        self.PT = pt0.copy()
        self.Trec = np.empty(nsteps + 1)
        self.Zrec = np.empty((nsteps + 1, N, m))
        self.PTrec = np.empty((nsteps + 1, N))
        self.dZrec = np.empty((0, N, m))
        self.status = self.done = None

    def timed(self):
        """Seconds of one run from the initial state; its states are in the records, status, done."""
        self.Z[:] = self.z0
        self.PT[:] = self.pt0
        start = time.perf_counter()
        self.status, self.done = self._run()
        return time.perf_counter() - start


class _Numba(_Runner):
    def __init__(self, setup, h, z0, pt0, nsteps):
        super().__init__(z0, pt0, nsteps)
        self.setup, self.h = setup, h
        # bench_ref.c's algorithm: the step matrix on linear scenes, whatever the ensemble size (a
        # family without a mirror is timed as a single trajectory runs: member by member)
        mirrored = family(setup.data).mirror(setup.data) is not None
        self.kernel = propagate_matrix if setup.scene.kernel.linear and mirrored else propagate_one

    def _run(self):
        return self.kernel(self.setup.data, self.setup.P, 0.0, self.h, self.Z, self.PT, self.nsteps, 1,
                           self.Trec, self.Zrec, self.PTrec, self.dZrec, NO_H, True, False)  # scaled, as bench_ref.c


class _C(_Runner):
    def __init__(self, lib, fields, setup, h, z0, pt0, nsteps):
        super().__init__(z0, pt0, nsteps)
        name, data = family(setup.data).mirror(setup.data)
        values = (_f64([getattr(setup.P, f) for f in fields]), _f64(setup.data.offsets))
        values += (len(values[1]), *data)
        N, m = z0.shape
        self.loop = _Loop(0.0, h, self.Z.ctypes.data, self.PT.ctypes.data, N, m, nsteps, 1,
                          self.Trec.ctypes.data, self.Zrec.ctypes.data, self.PTrec.ctypes.data,
                          self.dZrec.ctypes.data, 0, 0)
        self.fn = getattr(lib, name)
        self.fn.restype = ctypes.c_int
        self.values = values  # the arrays the C reads stay alive with the runner
        self.args = (ctypes.byref(self.loop), *(_c_arg(v) for v in values))

    def _run(self):
        status = self.fn(*self.args)
        return status, self.loop.done


def _pairs(args):
    scenes = [get_scene(s) for s in args.scenes] if args.scenes else list(SCENES.values())
    methods = [get_method(m) for m in args.methods] if args.methods else list(METHODS.values())
    pairs = [(s, m) for s in scenes for m in methods if m.refusal(s) is None]
    if not pairs:
        raise InputError("no method of --methods applies to a scene of --scenes: see 'cosymp methods'")
    return pairs


def _measure(setup, nsteps, lib, fields):
    """One row: ns/step of numba and C (min over interleaved repeats) and their agreement.

    lib: None, or the C reference built for the setup's scene; fields: the parameters the C
    mirror reads, None where it does not mirror the scene.
    """
    h = float(setup.scene.h)
    z0 = initial_states(setup)
    H0 = np.empty((1, z0.shape[0]))
    energies(setup.P, np.zeros(1), z0[None], H0)
    runners = [_Numba(setup, h, z0, -H0[0], nsteps)]
    mirrored = fields is not None and family(setup.data).mirror(setup.data) is not None
    if mirrored and lib is not None:
        runners.append(_C(lib, fields, setup, h, z0, -H0[0], nsteps))
    for r in runners:
        r.timed()
    best = [math.inf] * len(runners)
    start = time.perf_counter()
    repeats = 0
    while repeats < MIN_REPEATS or time.perf_counter() - start < BUDGET_S:
        for i, r in enumerate(runners):
            best[i] = min(best[i], r.timed())
        repeats += 1
    nb = runners[0]
    row = {"scene": setup.scene.name, "method": setup.method.name, "steps": int(nb.done),
           "status": int(nb.status), "numba_ns": 1e9 * best[0] / max(nb.done, 1),
           "c_ns": None, "ratio": None, "rel_diff": None, "agree": None, "mirrored": mirrored}
    if len(runners) > 1:
        c = runners[1]
        last = min(nb.done, nb.nsteps)  # the state each reached: its record (one trajectory's loop leaves Z as given)
        a = np.concatenate([nb.Zrec[last].ravel(), nb.PTrec[last]])
        b = np.concatenate([c.Zrec[last].ravel(), c.PTrec[last]])
        rel = float(np.max(np.abs(a - b)) / max(np.max(np.abs(a)), np.finfo(float).tiny))
        row["c_ns"] = 1e9 * best[1] / max(c.done, 1)
        row["ratio"] = row["numba_ns"] / row["c_ns"]
        row["rel_diff"] = rel
        row["agree"] = bool(c.status == nb.status and c.done == nb.done and rel < AGREE)
    return row


def _table(rows, out):
    out.write(f"{'scene':<10} {'method':<17} {'steps':>8} {'numba ns/step':>14} {'C ns/step':>10} "
              f"{'ratio':>6}\n")
    for r in rows:
        c = "" if r["c_ns"] is None else f"{r['c_ns']:.1f}"
        ratio = "" if r["ratio"] is None else f"{r['ratio']:.2f}"
        note = []
        if r["status"] != OK:
            note.append(f"stopped early: {STOPPED.get(r['status'], r['status'])}")
        if r["agree"] is False:
            note.append(f"WARNING: C and numba differ (rel {r['rel_diff']:.1e})")
        out.write(f"{r['scene']:<10} {r['method']:<17} {r['steps']:>8} {r['numba_ns']:>14.1f} {c:>10} "
                  f"{ratio:>6}  {'; '.join(note)}".rstrip() + "\n")
    unmirrored = {}
    for r in rows:
        if not r["mirrored"]:
            unmirrored.setdefault(r["scene"], []).append(r["method"])
    if unmirrored:
        pairs = "; ".join(f"{scene}: {', '.join(methods)}" for scene, methods in unmirrored.items())
        out.write(f"no C mirror in bench_ref.c (numba figures only) for {pairs}\n")
    rated = [r for r in rows if r["ratio"] is not None]
    if rated:
        worst = max(rated, key=lambda r: r["ratio"])
        met = sum(r["ratio"] <= TARGET for r in rated)
        out.write(f"ratio <= {TARGET} for {met} of {len(rated)} pairs; worst {worst['ratio']:.2f} "
                  f"({worst['scene']} {worst['method']})\n")


def bench(args, out, err):
    """Print (or, with args.json, write as a JSON list) one row per scene x applicable method, with
    progress on err (progress.shown: a bar on a terminal, else a line per pair)."""
    if args.steps < 1:
        raise InputError(f"--steps {args.steps} must be at least 1")
    pairs = _pairs(args)
    widest = max(2 * s.ndof + 1 for s, _ in pairs)
    if (args.steps + 1) * widest > MAX_RECORDED:
        raise InputError(f"--steps {args.steps} records more than {MAX_RECORDED:.0e} values: "
                         f"pass at most {MAX_RECORDED // widest - 1}")
    say = (err if args.json else out).write
    have_source = C_SOURCE.is_file()
    have_cc = have_source and shutil.which(CC) is not None
    if not have_source:
        say(f"the C reference {C_SOURCE.parent.name}/{C_SOURCE.name} is not in this installation (it is in "
            "cosymp's source checkout: run the bench from there): numba figures only, no C reference or ratio\n")
    elif not have_cc:
        say(f"{CC} not found: numba figures only, no C reference or ratio\n")
    elif not args.json:
        out.write(f"C reference: {CC} {' '.join(CFLAGS)}; numba/C ratio target <= {TARGET}\n")
    mirror = mirrored_scenes() if have_source else {}
    rows = []
    with tempfile.TemporaryDirectory(prefix="cosymp-bench-") as workdir, shown(err) as progress:
        libs = {}
        for i, (scene, method) in enumerate(pairs):
            progress(i, len(pairs), f"{scene.name} {method.name}")
            fields = mirror.get(scene.name)
            if have_cc and fields is not None and scene.name not in libs:
                libs[scene.name] = _compile(scene, workdir)
            rows.append(_measure(Setup.make(scene, method), args.steps, libs.get(scene.name), fields))
        progress(len(pairs), len(pairs), "done")
    if args.json:
        out.write(json.dumps(rows) + "\n")
    else:
        _table(rows, out)
