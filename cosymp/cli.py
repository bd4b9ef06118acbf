"""The `cosymp` command line: run, scenes, methods, workprecision, report, sweep, compile, bench.

The long commands (workprecision, report, sweep, bench) report their progress on stderr, a bar on a
terminal and a line per stage otherwise (progress.shown); workprecision, report and sweep first
compile the kernels they need that the cache lacks, a line each. stdout holds the results alone.

Exit codes: 0 done, 2 bad input (one line on stderr saying what to change), 3 a run that
could not go on (overflow, Newton), also one line.
"""
import argparse
import json
import math
import os
import shlex
import sys
import time
from functools import partial

from .errors import CosympError, InputError, RunError, one_line


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        message = one_line(message, 300)
        raise InputError(f"{message} (see 'cosymp {self.prog.split()[-1]} --help')"
                         if " " in self.prog else f"{message} (see 'cosymp --help')")


def _number(text):
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None


def _assignment(text):
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"'{text}' is not NAME=VALUE")
    return name.strip(), value.strip()


def parser():
    p = _Parser(prog="cosymp", allow_abbrev=False, description="Structure-preserving integrators for time-dependent "
                "Hamiltonian systems on the extended phase space.")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run one scene with one method and print its figures")
    r.add_argument("scene")
    r.add_argument("--method", default="midpoint")
    r.add_argument("--h", type=_number, help="step size (default: the scene's paper value)")
    r.add_argument("--T", type=_number, help="horizon (default: the scene's paper value)")
    r.add_argument("--theta", type=_number, help="theta in [0, 1] for theta and theta-naive")
    r.add_argument("--gauge", help="gauge of a scene with gauges (default original)")
    r.add_argument("--transport-from", help="run in this gauge and transport each step into --gauge")
    r.add_argument("--set", type=_assignment, action="append", default=[], metavar="NAME=VALUE",
                   help="a scene parameter, e.g. --set gamma=0.5 or --set 'beta=0.05*(1+tanh(t))'")
    r.add_argument("--no-error", action="store_true", help="skip the reference solution")
    r.add_argument("--json", action="store_true", help="print one JSON object")
    w = sub.add_parser("workprecision", help="error against cost for the methods (and scipy's solvers) on one "
                       "scene; --long: error and H + p_t drift as T grows")
    w.add_argument("scene")
    w.add_argument("--methods", nargs="+", help="methods to compare (default: those of the work-precision "
                   "set that apply, the splittings by leapfrog and blanes-moan6; `cosymp methods` lists all)")
    w.add_argument("--peers", action="store_true", help="add scipy solve_ivp RK45, DOP853 and LSODA at rtol = atol "
                   "from 1e-3 to 1e-13")
    w.add_argument("--T", type=_number, help="horizon (default: the scene's paper value)")
    w.add_argument("--h", type=_number, nargs="+", help="step sizes (default: refine from the scene's time "
                   "scale by sqrt(2) until the round-off floor or --max-steps); with --long, one step size")
    w.add_argument("--theta", type=_number, help="theta for theta and theta-naive")
    w.add_argument("--set", type=_assignment, action="append", default=[], metavar="NAME=VALUE",
                   help="a scene parameter, e.g. --set gamma=2e-4")
    w.add_argument("--max-steps", type=int, default=1 << 20, help="largest step count per run (default 2^20)")
    w.add_argument("--budget", type=_number, default=0.2, help="seconds of timed repeats per run (default 0.2)")
    w.add_argument("--long", action="store_true", help="long horizons: each method at one h (default the "
                   "scene's) to T = 1e2 ... 1e6 (at most 1e7 steps)")
    w.add_argument("--horizons", type=_number, nargs="+", help="horizons for --long")
    w.add_argument("--out", help="write every run as tidy data to FILE.csv or FILE.json")
    rp = sub.add_parser("report", help="a self-contained HTML report of one comparison (SCENE) or of the "
                        "paper's Sections 4 and 5 (paper)")
    rp.add_argument("target", metavar="SCENE|paper")
    rp.add_argument("--method", help="the method (default midpoint)")
    rp.add_argument("--vs", help="the method it is compared with (default rk4)")
    rp.add_argument("--h", type=_number, help="step size (default: the scene's paper value)")
    rp.add_argument("--T", type=_number, help="horizon (default: the scene's paper value)")
    rp.add_argument("--theta", type=_number, help="theta in [0, 1] for theta and theta-naive")
    rp.add_argument("--set", type=_assignment, action="append", default=[], metavar="NAME=VALUE",
                    help="a scene parameter, e.g. --set gamma=0.5")
    rp.add_argument("--quick", action="store_true", help="paper: leave out the long runs (5e5 and 2e5)")
    rp.add_argument("--no-work-precision", action="store_true", help="paper: leave out the work-precision diagram")
    rp.add_argument("-o", "--out", required=True, metavar="FILE.html")
    sw = sub.add_parser("sweep", help="a measure of one method over a grid of parameters (a stability map), "
                        "in-process or on a Dask cluster")
    sw.add_argument("scene")
    sw.add_argument("--method", default="midpoint")
    sw.add_argument("--vary", action="append", default=[], metavar="NAME=START:STOP:NUM[:log]",
                    help="a varied scene parameter, h, T or theta, e.g. --vary eps=0:0.6:50 (repeat for a grid)")
    sw.add_argument("--measure", nargs="+", default=["growth"], metavar="MEASURE",
                    help="one or more of H_ext_max_abs, det_max_dev, error_final, growth (default growth)")
    sw.add_argument("--h", type=_number, help="step size where h is not varied (default: the scene's)")
    sw.add_argument("--T", type=_number, help="horizon where T is not varied (default: the scene's)")
    sw.add_argument("--theta", type=_number, help="theta for theta and theta-naive")
    sw.add_argument("--set", type=_assignment, action="append", default=[], metavar="NAME=VALUE",
                    help="a fixed scene parameter, e.g. --set q0=3.14159")
    where = sw.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, help="start a Dask LocalCluster of N worker processes")
    where.add_argument("--scheduler", metavar="ADDRESS", help="use a running Dask cluster, e.g. tcp://10.0.0.5:8786")
    sw.add_argument("-o", "--out", required=True, metavar="FILE.csv|FILE.parquet")
    sub.add_parser("scenes", help="list the scenes with their parameters and defaults")
    sub.add_parser("methods", help="list the methods")
    c = sub.add_parser("compile", help="compile every kernel into numba's disk cache now, one process per core "
                       "(otherwise each is compiled on first use)")
    c.add_argument("--processes", type=int, help="worker processes (default: one per core)")
    b = sub.add_parser("bench", help="ns/step per scene and method against a C -O3 loop")
    b.add_argument("--steps", type=int, default=200_000)
    b.add_argument("--scenes", nargs="*")
    b.add_argument("--methods", nargs="*")
    b.add_argument("--json", action="store_true")
    return p


def _run(args, out):
    from .integrate import Setup, get_scene
    from .reference import is_resolved
    from .scenes import SCENES
    from .summary import run_summary

    scene = get_scene(args.scene)
    values = dict(args.set)
    if args.gauge is not None or args.transport_from is not None:
        if not scene.has_gauges:
            gauged = ", ".join(f"'{s.name}'" for s in SCENES.values() if s.has_gauges)
            raise InputError(f"scene '{scene.name}' has no gauges: --gauge and --transport-from "
                             f"apply to {gauged}")
        for g in (args.gauge, args.transport_from):
            if g is not None:
                scene.values({"gauge": g})
        if args.gauge is not None:
            values["gauge"] = args.gauge
    setup = Setup.make(scene, args.method, values, args.theta)
    h = scene.h if args.h is None else args.h
    T = scene.T if args.T is None else args.T
    res = run_summary(setup, h, T, transport_from=args.transport_from, with_error=not args.no_error)
    if args.json:
        out.write(json.dumps(res) + "\n")
        return
    lines = [f"{res['scene']} with {res['method']}" + (f" (theta = {res['theta']})" if res["theta"] is not None else "")
             + (f", gauge {res['gauge']}" if res["gauge"] else "")
             + (f" transported from {res['transport_from']}" if res["transport_from"] else ""),
             f"  h = {h:g}, steps = {res['steps']}, t_final = {res['t_final']:g}",
             f"  q(T) = {_fmt(res['q_final'])}, p(T) = {_fmt(res['p_final'])}, p_t(T) = {res['pt_final']:.6g}"]
    if "Pi_final" in res:
        lines.append(f"  mechanical momentum Pi(T) = {_fmt(res['Pi_final'])}")
    lines += [f"  max |H + p_t|          = {res['H_ext_max_abs']:.3e}",
              f"  max |det M_k - 1|      = {res['det_max_dev']:.3e}",
              f"  max |M^T J M - J|      = {res['symp_max_dev']:.3e}"]
    if res["error_final"] is not None:
        unc = res["reference_uncertainty"]
        own = ""  # an exact flow's, 0, goes unsaid
        if unc is None:  # infinite: its check at twice its step overflowed
            own = " (the reference's own: unbounded, its check at twice its step overflowed: the run's error is not resolved)"
        elif unc > 0:
            own = (f" (the reference's own, estimated: {unc:.1e}"
                   + ("; at least as large: the run's error is not resolved)"
                      if not is_resolved(res["error_final"], unc) else ")"))
        lines.append(f"  relative error at T vs {res['reference']} = {res['error_final']:.3e}{own}")
    lines.append(f"  integration time {res['wall_s']:.3f} s (total {res['wall_total_s']:.3f} s)")
    out.write("\n".join(lines) + "\n")


def _workprecision(args, out, err):
    from . import workprecision as wp
    from .integrate import MAX_STEPS
    from .progress import shown

    if args.out:
        _writable(args.out, (".csv", ".json"), "--out", "a .csv or .json file")
    if not 1 <= args.max_steps <= MAX_STEPS:
        raise InputError(f"--max-steps {args.max_steps} must be between 1 and {MAX_STEPS:.0e}")
    if not (math.isfinite(args.budget) and args.budget > 0):
        raise InputError(f"--budget {args.budget} must be a positive number of seconds")
    if args.long and args.peers:
        raise InputError("--peers compares costs at one horizon: drop it with --long")
    if args.long and args.T is not None:
        raise InputError("--long runs to the --horizons (default 1e2 ... 1e6): drop --T")
    values = dict(args.set)
    if args.long and args.h is not None and len(args.h) != 1:
        raise InputError("--long runs every method at one step size: pass one --h")
    with shown(err) as progress:
        compile_first = partial(_compile_first, err=err)
        if args.long:
            rows = wp.drift(args.scene, args.methods or wp.DRIFT_METHODS, values, None if args.h is None else args.h[0],
                            args.horizons, args.theta, progress=progress, prepare=compile_first)
        else:
            rows = wp.measure(args.scene, args.methods, values, args.T, args.h, args.theta, args.peers,
                              max_steps=args.max_steps, budget=args.budget, progress=progress, prepare=compile_first)
    if args.out:
        wp.write_rows(rows, args.out, wp.DRIFT_FIELDS if args.long else wp.ROW_FIELDS)
    out.write(_drift_table(rows) if args.long else _cost_table(rows))
    if args.out:
        out.write(f"{len(rows)} runs written to {args.out}\n")


def _sweep(args, out, err):
    from . import sweep
    from .progress import shown

    _writable(args.out, sweep.FORMATS, "--out", "a .csv or .parquet file")
    p = sweep.plan(args.scene, args.method, args.vary, args.measure, dict(args.set), args.theta, args.h, args.T)
    _compile_first(p.unit_keys(), err)
    with shown(err) as progress:
        res = sweep.run(p, workers=args.workers, scheduler=args.scheduler, progress=progress)
    try:
        sweep.write(res, args.out)
    except OSError as e:
        raise InputError(f"cannot write {args.out}: {e.strerror or e}; choose another file") from None
    out.write(sweep.summary(res) + f"  written to {args.out}\n")


def _writable(path, suffixes, option, what):
    """InputError before any work if `path` has the wrong suffix, is a folder or its folder cannot be
    written."""
    if not path.endswith(suffixes):
        raise InputError(f"{option} {path}: name {what}")
    if os.path.isdir(path):
        raise InputError(f"cannot write {path}: it is a folder; choose another file")
    folder = os.path.dirname(os.path.abspath(path))
    if not (os.path.isdir(folder) and os.access(folder, os.W_OK)):
        raise InputError(f"cannot write {path}: {folder} is not a writable folder; choose another file")


def _report(args, out, err):
    """A report: its input checked, then the kernels it needs that the cache lacks compiled with a
    line per unit, then computed with a line per stage on stderr (a bar on a terminal): on a cold
    cache the paper report otherwise printed nothing for minutes."""
    from . import warm
    from .integrate import Setup, check_step, get_scene
    from .methods import method
    from .progress import shown
    from .reference import check_reference
    from .report import write

    _writable(args.out, (".html", ".htm"), "-o", "an .html file")
    _report_options(args)
    if args.target == "paper":
        from .report.paper import kernels, paper_report

        keys = [k for scene, methods in kernels(not args.no_work_precision).items()
                for k in warm.unit_keys(scene, methods)]
    else:
        from .report.scene import command, scene_report

        scene = get_scene(args.target)
        values = dict(args.set)
        setups = [Setup.make(scene, m, values, args.theta if method(m).takes_theta else None)
                  for m in _report_methods(args)]
        h = scene.h if args.h is None else args.h
        T = scene.T if args.T is None else args.T
        end = check_step(h, T) * h
        check_reference(setups[0], h, T)
        scene.check_horizon(setups[0].values, end)
        keys = warm.run_keys(scene, [s.method.name for s in setups])
    _compile_first(keys, err)
    with shown(err) as progress:
        if args.target == "paper":
            cmd = " ".join(["cosymp report paper"] + ["--quick"] * args.quick
                           + ["--no-work-precision"] * args.no_work_precision + ["-o", shlex.quote(args.out)])
            report = paper_report(progress, long=not args.quick, work_precision=not args.no_work_precision,
                                  command=cmd)
        else:
            report = scene_report(setups, h, T, command(setups, h, T, args.out), progress=progress)
    try:
        size = write(report, args.out)
    except OSError as e:
        raise InputError(f"cannot write {args.out}: {e.strerror}; choose another file") from None
    out.write(f"report written to {args.out} ({size / 1e6:.2f} MB)\n")


def _report_methods(args):
    """A scene report's two methods: --method (default midpoint) and --vs (default rk4)."""
    return args.method or "midpoint", args.vs or "rk4"


def _report_options(args):
    """InputError for an option the report asked for does not take (it was ignored without a word):
    the paper report runs the paper's own values, only it has long runs and a diagram to leave out,
    and θ is for the methods that take it."""
    from .methods import THETA_APPLIES, method

    if args.target == "paper":
        given = [f"--{name}" for name in ("method", "vs", "h", "T", "theta") if getattr(args, name) is not None]
        given += ["--set"] * bool(args.set)
    else:
        given = [flag for flag, on in (("--quick", args.quick), ("--no-work-precision", args.no_work_precision)) if on]
        names = _report_methods(args)
        if args.theta is not None and not any(method(m).takes_theta for m in names):
            raise InputError(f"--{THETA_APPLIES}, and neither {names[0]} nor {names[1]} is one: drop it, or choose "
                             "one with --method or --vs")
    if given:
        what = ("a scene's report (cosymp report SCENE); the paper report runs the paper's own values"
                if args.target == "paper" else "the paper report (cosymp report paper) only")
        raise InputError(f"{', '.join(given)} appl{'y' if len(given) > 1 else 'ies'} to {what}: "
                         f"drop {'them' if len(given) > 1 else 'it'}")


def _compile_first(keys, err):
    """Compile the kernel units with these keys that the cache lacks, in one process per core, a
    line on stderr for each; CosympError if one fails."""
    from . import warm

    def say(line):
        err.write(f"cosymp: {line}\n")
        err.flush()

    compiler = warm.compile_missing(keys, report=say)
    if compiler is not None and compiler.failed:
        raise _compile_failure(compiler)


def _compile_failure(compiler):
    key, why = next(iter(compiler.failed.items()))
    return CosympError(f"{len(compiler.failed)} of {compiler.total} groups of kernels failed to compile, e.g. {key}: "
                       f"{why}")


def _num(x, spec):
    """x formatted to spec, or '–' in its width where it is not a number (never reached, failed)."""
    return format(x, spec) if math.isfinite(x) else "–".rjust(int(spec.split(".")[0]))


def _cost_table(rows):
    from .workprecision import targets

    t = targets(rows)
    first = rows[0]
    lines = [f"{first['scene']} to T = {first['T']:g}; error = |z - z_ref| / |z_ref| at T, z_ref: {first['reference']}"
             + (f" (uncertainty {first['reference_uncertainty']:.1e})" if first["reference_uncertainty"] else ""),
             (f"{'solver':18s} {'runs':>4s} {'failed':>6s} {'best error':>10s} {'s to 1e-6':>10s} "
              f"{'s to 1e-9':>10s} {'max|H~|':>9s} {'max|detM-1|':>11s}")]
    for solver, c6 in t["cost"][1e-6].items():
        mine = [r for r in rows if r["solver"] == solver]
        ok = [r for r in mine if r["error"] == r["error"]]
        best = min(ok, key=lambda r: r["error"]) if ok else None
        lines.append(f"{solver:18s} {len(mine):4d} {len(mine) - len(ok):6d} "
                     f"{_num(best['error'] if best else math.nan, '10.2e')} {_num(c6, '10.2e')} "
                     f"{_num(t['cost'][1e-9][solver], '10.2e')} "
                     f"{_num(max((r['H_ext_max_abs'] for r in ok), default=math.nan), '9.1e')} "
                     f"{_num(max((r['det_max_dev'] for r in ok), default=math.nan), '11.1e')}")
    for e, r in t["ratios"].items():
        if r["fastest"] is None:
            lines.append(f"at error {e:.0e}: no cosymp method got there (use smaller steps: --max-steps)")
            continue
        parts = [f"fastest cosymp method {r['fastest']}"]
        if math.isfinite(r["dop853_over_fastest"]):
            parts.append(f"scipy DOP853 / fastest = {r['dop853_over_fastest']:.3g}")
        if math.isfinite(r["symplectic_over_rk4"]):
            parts.append(f"best symplectic ({r['best_symplectic']}) / rk4 = {r['symplectic_over_rk4']:.3g}")
        lines.append(f"at error {e:.0e}: " + "; ".join(parts))
    return "\n".join(lines) + "\n"


def _drift_table(rows):
    from .workprecision import ROUNDOFF, growth_text

    horizons = sorted({r["T"] for r in rows})
    shown = [T for T in horizons if abs(math.log10(T) - round(math.log10(T))) < 1e-6] or horizons
    first = rows[0]
    lines = [(f"{first['scene']}: relative error at T and max |H + p_t| up to T, one step size per method; "
              f"reference: {first['reference']}"),
             f"{'solver':18s} {'h':>7s} " + " ".join(f"{f'err T={T:g}':>11s}" for T in shown)
             + f" {'err slope':>9s} {'max|H~|':>9s} {'H~ slope':>9s}"]
    for solver in dict.fromkeys(r["solver"] for r in rows):
        mine = {r["T"]: r for r in rows if r["solver"] == solver}
        last = mine[horizons[-1]]
        lines.append(f"{solver:18s} {last['h']:7.3g} " + " ".join(_num(mine[T]["error"], "11.2e") for T in shown)
                     + f" {growth_text(rows, solver):>9s} {_num(last['H_ext_max_abs'], '9.1e')} "
                     f"{growth_text(rows, solver, 'H_ext_max_abs'):>9s}")
        if last["status"] != "ok":
            lines.append(f"  {solver}: {last['status']}")
    lines.append("slope: fitted exponent of T over the horizons where the error is below 0.1 (1 = linear growth, "
                 "2 = quadratic); –: fewer than 3 such horizons; round-off: every value within "
                 f"{ROUNDOFF:g} eps |H| sqrt(N) after N steps (the relative error: {ROUNDOFF:g} eps sqrt(N)), the "
                 "rounding of N steps, not the method")
    return "\n".join(lines) + "\n"


def _fmt(v):
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def _compile(args, out):
    from . import warm

    if args.processes is not None and not 1 <= args.processes <= 256:
        raise InputError(f"--processes {args.processes} must be between 1 and 256")

    def report(line):
        out.write(f"cosymp: {line}\n")
        out.flush()

    compiler = warm.compile_all(processes=args.processes, report=report)
    if not compiler.total:
        report("every kernel is in the cache")
    elif compiler.failed:
        raise _compile_failure(compiler)
    else:
        report(f"done in {time.perf_counter() - compiler.started:.1f} s")


def _scenes(out):
    from .scenes import SCENES

    for s in SCENES.values():
        out.write(f"{s.name}: {s.title}\n  {s.summary}\n  paper defaults: h = {s.h:g}, T = {s.T:g}\n")
        for p in s.params:
            rng = f" in {list(p.choices)}" if p.choices else (
                f" in [{p.bounds[0]:g}, {p.bounds[1]:g}]" if all(map(math.isfinite, p.bounds)) else "")
            out.write(f"    {p.name} = {p.default}{rng}: {p.doc}\n")


def _methods(out):
    from .methods import METHODS

    for m in METHODS.values():
        order = "order 2 at theta = 1/2, else 1" if m.takes_theta else (
            "exact" if m.name == "exact" else f"order {m.order}")
        preserves = m.preserves if m.preserves_at(0.0) == m.preserves else f"{m.preserves} at theta = 1/2, else none"
        out.write(f"{m.name}: {m.title} ({order}; preserves: {preserves})\n  {m.doc}\n")


def main(argv=None, out=None, err=None):
    out = out or sys.stdout
    err = err or sys.stderr
    try:
        args = parser().parse_args(argv)
        if args.command == "run":
            _run(args, out)
        elif args.command == "scenes":
            _scenes(out)
        elif args.command == "methods":
            _methods(out)
        elif args.command == "workprecision":
            _workprecision(args, out, err)
        elif args.command == "report":
            _report(args, out, err)
        elif args.command == "sweep":
            _sweep(args, out, err)
        elif args.command == "compile":
            _compile(args, out)
        else:
            from .bench import bench

            bench(args, out, err)
    except InputError as e:
        err.write(f"cosymp: {e}\n")
        return 2
    except (RunError, CosympError) as e:
        err.write(f"cosymp: {e}\n")
        return 3
    except KeyboardInterrupt:
        err.write("cosymp: interrupted\n")
        return 130
    return 0
