"""The `cosymp` command line: run, scenes, methods, bench.

Exit codes: 0 done, 2 bad input (one line on stderr saying what to change), 3 a run that
could not go on (overflow, Newton), also one line.
"""
import argparse
import json
import math
import sys

from .errors import CosympError, InputError, RunError


class _Parser(argparse.ArgumentParser):
    def error(self, message):
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
    r.add_argument("--gauge", help="gauge of the charged scene (default original)")
    r.add_argument("--transport-from", help="run in this gauge and transport each step into --gauge")
    r.add_argument("--set", type=_assignment, action="append", default=[], metavar="NAME=VALUE",
                   help="a scene parameter, e.g. --set gamma=0.5 or --set 'beta=0.05*(1+tanh(t))'")
    r.add_argument("--no-error", action="store_true", help="skip the reference solution")
    r.add_argument("--json", action="store_true", help="print one JSON object")
    sub.add_parser("scenes", help="list the scenes with their parameters and defaults")
    sub.add_parser("methods", help="list the methods")
    b = sub.add_parser("bench", help="ns/step per scene and method against a C -O3 loop")
    b.add_argument("--steps", type=int, default=200_000)
    b.add_argument("--scenes", nargs="*")
    b.add_argument("--methods", nargs="*")
    b.add_argument("--json", action="store_true")
    return p


def _run(args, out):
    from .integrate import Setup, get_scene
    from .summary import run_summary

    scene = get_scene(args.scene)
    values = dict(args.set)
    if args.gauge is not None or args.transport_from is not None:
        if scene.name != "charged":
            raise InputError(f"scene '{scene.name}' has no gauges: --gauge and --transport-from "
                             f"apply to 'charged'")
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
        lines.append(f"  error at T vs {res['reference']} = {res['error_final']:.3e}")
    lines.append(f"  integration time {res['wall_s']:.3f} s (total {res['wall_total_s']:.3f} s)")
    out.write("\n".join(lines) + "\n")


def _fmt(v):
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


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
        out.write(f"{m.name}: {m.title} ({order}; preserves: {m.preserves})\n  {m.doc}\n")


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
        else:
            from .bench import bench

            bench(args, out)
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
