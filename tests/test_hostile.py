"""Hostile input: property-based tests over scenes x methods x parameters x typed beta(t).

The contract under test: whatever a caller passes (Python API, `cosymp` command line, the app's
Study), the answer is a result or an error that says, in one line, what to change; never another
exception, a traceback or a hang. Typed beta(t) expressions never reach Python: attribute access,
other names, dunder tricks, huge exponents, deep nesting and very long input are rejected quickly
while eval, exec and compile are replaced by functions that raise.

Everything is derandomized and database-free, so a run in CI generates the same inputs as here.
The expression grammar itself is covered by test_expr.py; these tests go through the scene's
beta parameter, Setup.make, simulate, the CLI and the app state.
"""
import builtins
import contextlib
import io
import math
import re
import shutil
import tempfile
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from conftest import pairs
from cosymp.cli import main
from cosymp.errors import InputError, RunError
from cosymp.expr import FUNCTIONS, MAX_LENGTH
from cosymp.integrate import Setup, check_step, get_scene, simulate
from cosymp.methods import METHODS
from cosymp.scenes import SCENES
from cosymp.scenes.charged import GAUGES

CASES = pairs()
BETA = next(p for p in SCENES["charged"].params if p.name == "beta")
MAX_MESSAGE = 1000
"""A message longer than this is not 'a clear message' (it echoes the input instead of naming it)."""
ACTIONS = re.compile(r"\b(?:reduce|increase|shorten|choose|must|pass|use|write|put|add|simplify|raise|drop|"
                     r"leave|group|name)\b|allowed|not supported|see 'cosymp", re.IGNORECASE)
INPUT_NAMES = sorted({"h", "T", "theta", "scene", "method", "beta", "stride", "initial states", "gauge"}
                     | {p.name for s in SCENES.values() for p in s.params})
NAMED = re.compile(r"(?<![\w])(?:" + "|".join(map(re.escape, INPUT_NAMES)) + r")(?![\w])")
SETTINGS = {"derandomize": True, "database": None, "print_blob": False,
            "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large,
                                      HealthCheck.filter_too_much]}


def assert_clear(message):
    """One non-empty line of bounded length that names an input or says what to do."""
    assert message.strip(), "empty message"
    assert len(message.splitlines()) == 1, f"multi-line message: {message[:300]!r}"
    assert len(message) <= MAX_MESSAGE, f"message of {len(message)} characters: {message[:120]!r}..."
    assert NAMED.search(message) or ACTIONS.search(message), f"message names nothing to change: {message!r}"


def _boom(*args, **kwargs):
    raise AssertionError("eval/exec/compile reached from user input")


@contextlib.contextmanager
def no_dynamic_code():
    """builtins.eval, exec and compile raise inside the block (restored before any assertion,
    so that pytest's own reporting, which compiles, is unaffected)."""
    with pytest.MonkeyPatch.context() as mp:
        for name in ("eval", "exec", "compile"):
            mp.setattr(builtins, name, _boom)
        yield


def outcome(fn, *args):
    """('ok', value) or ('error', exception) for cosymp's own errors; anything else propagates."""
    try:
        return "ok", fn(*args)
    except (InputError, RunError) as err:
        return "error", err


# ---------------------------------------------------------------- warm-up (compilation, untimed)


def _warm_setups():
    for scene, method, theta in CASES:
        simulate(Setup.make(scene, method, None, theta), 0.01, 0.03)
    for method in ("midpoint", "gauss6", "rk4", "boris"):
        simulate(Setup.make("charged", method, {"beta": "0.05*(1+tanh(t))"}), 0.01, 0.03)
    BETA.check("sin(t)^2 + exp(-t)")


@pytest.fixture(scope="module", autouse=True)
def warm():
    """Compile every (scene, method) loop and the expression evaluator before any timing or deadline."""
    _warm_setups()


# ---------------------------------------------------------------- strategies

NUMBERS = st.one_of(
    st.integers(0, 1000).map(str),
    st.floats(0, 100, allow_nan=False).map(lambda x: repr(round(x, 3))),
    st.sampled_from(["0.5", ".25", "3.", "1e-3", "2.5E+2", "1e300", "1e-300", "5e-324", "1.7e308"]),
)


@st.composite
def grammar(draw, depth=3):
    """Text of a grammar-valid expression of t (numbers, t, pi, + - * / ^, the functions),
    with random spacing and only the parentheses a function call needs."""
    if depth == 0 or draw(st.integers(0, 2)) == 0:
        return draw(st.one_of(st.sampled_from(["t", "pi", "t", "-t"]), NUMBERS))
    space = draw(st.sampled_from(["", " ", "  ", "\t"]))
    kind = draw(st.sampled_from(["binary", "binary", "unary", "call", "group"]))
    if kind == "binary":
        op = draw(st.sampled_from("+-*/^"))
        return f"{draw(grammar(depth - 1))}{space}{op}{space}{draw(grammar(depth - 1))}"
    if kind == "unary":
        return draw(st.sampled_from("+-")) + draw(grammar(depth - 1))
    if kind == "group":
        return f"({space}{draw(grammar(depth - 1))}{space})"
    return f"{draw(st.sampled_from(FUNCTIONS))}({draw(grammar(depth - 1))})"


ATTACKS = [
    # attribute access and dunder tricks
    "t.__class__", "().__class__.__bases__", "().__class__.__bases__[0].__subclasses__()",
    "t.__class__.__mro__[1].__subclasses__()", "sin.__globals__", "t.real", "pi.__doc__",
    "(t).__class__", "1 .__class__", "1.0.__class__", "getattr(t, '__class__')", "__builtins__",
    "__import__('os').system('x')", "__import__", "__class__", "__dict__", "_", "__",
    # names other than t, pi and the functions
    "x", "os", "eval", "exec", "compile", "lambda", "lambda t: t", "lambda: 0", "eval('1')", "exec('1')",
    "open('/etc/passwd')", "globals()", "locals()", "vars()", "dir()", "input()", "breakpoint()", "abs(t)",
    "math.sin(t)", "np.sin(t)", "numpy", "e", "E", "inf", "nan", "Infinity", "T", "Sin(t)", "SIN(t)", "tt",
    "t1", "pi2", "None", "True", "print(t)", "yield t", "await t", "import os", "self", "beta",
    # Python syntax that is not the grammar
    "f'{t}'", 'f"{1}"', "'t'", '"t"', "b't'", "r't'", "t;1", "t; import os", "t\n;import os", "[t]", "t[0]",
    "{t}", "{'a': t}", "sin(t, 2)", "(t, t)", "t,", "sin(t=1)", "sin(x=t)", "sin(*t)", "sin(**t)",
    "t if t else 1", "t and 1", "t or 1", "not t", "t == 1", "t < 1", "t % 2", "t // 2", "t ** 2",
    "t @ t", "~t", "t << 2", "t & 1", "t | 1", "t ^^ 2", "$t", "`t`", "\\t", "#t", "t # comment", "t:=1",
    "t = 1", "t += 1", "2j", "1j*t", "0x10", "0b1", "0o7", "1_000", "t!", "t?", "@t", "sin(t)(t)",
    "sin(t))", "((t)", "sin", "sin()", "()", "",
    # unicode lookalikes, fullwidth digits, invisible characters, null bytes
    "ｔ", "ｓｉｎ(t)", "\u0455in(t)", "si\uff4e(t)", "t\u200b", "\u200bt", "t\u0307", "１", "t*２", "t\u00a0+1",
    "\U0001d461", "\u0663", "t\u00b2", "\u03c0", "\u221e", "\u2212t", "t\u2217t", "t\uff0bt", "\ufeff+t",
    "\x00", "t\x00", "\x00t", "sin(t)\x00; import os", "t\x1b[2J", "t\u2028+1", "t\r;1", "t\x85;1",
    # huge exponents and numbers
    "9^9^9^9", "10^10^10", "2^1024", "1e999", "1e308*1e308", "exp(1e308)", "(1+t)^1e308",
    "exp(exp(exp(exp(t+10))))", "t^9^9^9", "-1e999", "9" * 400,
    # deep nesting
    "(" * 10_000 + "t" + ")" * 10_000, "-" * 10_000 + "t", "+" * 10_000 + "t",
    "sin(" * 10_000 + "t" + ")" * 10_000, "2^" * 10_000 + "t", "(" * 200 + "t" + ")" * 200,
    "-" * 400 + "t", "+" * 400 + "t", "sin(" * 60 + "t" + ")" * 60, "2^" * 100 + "t", "(" * 10_000,
    # very long input
    "t+" * 500_000 + "t", "t" * 1_000_000, "(" * 1_000_000, "1" * 1_000_000, "+".join(["t"] * 300),
]
HUGE = {"t^1e308", "-t^1e308", "t^1e300", "1e300*t^300", "exp(t)^1000", "exp(1000*t)", "1e160",
        "1e154*(1+t)", "2^1023*t"}
"""Numeric expressions that parse (finite with their derivatives at t = 0) but leave floating-point
range later or at once; they must give a RunError that says what to change."""

HOSTILE_TEXT = st.one_of(
    st.sampled_from([a for a in ATTACKS if len(a) <= 2 * MAX_LENGTH]),
    st.text(max_size=40),
    st.text(alphabet="0123456789.eE+-*/^() tpisncoxglqrh_,;'\"[]{}!@#$%&|~`<>?:=\\\n\x00²é",
            max_size=60),
    st.builds(lambda a, b, c: a + b + c, grammar(2), st.sampled_from([".__class__", ";", ",", "[0]", "**2",
                                                                       " x", "\n", "\x00", "'"]), grammar(1)),
    st.sampled_from(sorted(HUGE)),
)
BETA_TEXT = st.one_of(grammar(), HOSTILE_TEXT, st.sampled_from(["paper", "constant", " paper ", "Paper"]))


def _in_bounds(p):
    lo, hi = p.bounds
    return st.floats(max(lo, -1e3), min(hi, 1e3), allow_nan=False)


def _out_of_bounds(p):
    lo, hi = p.bounds
    above = st.floats(1e-9, 1e300).map(lambda d: hi + max(d, abs(hi) * 1e-6)) if math.isfinite(hi) else st.nothing()
    below = st.floats(1e-9, 1e300).map(lambda d: lo - max(d, abs(lo) * 1e-6)) if math.isfinite(lo) else st.nothing()
    edge = st.sampled_from([1e308, -1e308, 1e-320, -1e-320]).filter(lambda x: not lo <= x <= hi)
    return st.one_of(above, below, edge)


ODD_VALUES = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, None, "", " ", "abc", "nan", "inf", "1e999", "0x10",
                     "1_0", "１", "1\n2", b"1", [1.0], {}, (), object, True, 1j, 10 ** 400, -(10 ** 400),
                     np.float32(0.5), np.nan]),
    st.text(max_size=12),
)


GOOD_BAD_ODD = ["good"] * 5 + ["bad", "odd"]
ONE_IN_TEN = [False] * 9 + [True]
"""Choices by label: hypothesis favours boundary integers, so `integers(0, 9) == 0` is far likelier than 1 in 10."""


@st.composite
def overrides(draw, scene):
    """Parameter overrides for a scene, most of them usable: in-bounds values (5 in 7), out-of-bounds,
    non-finite and odd types, unknown names, and for charged random beta(t) text (grammar-valid or
    hostile) and gauges."""
    out = {}
    for p in draw(st.lists(st.sampled_from(scene.params), max_size=3, unique_by=lambda p: p.name)):
        if p.choices:
            good = st.sampled_from(p.choices)
        elif p.name == "beta":
            good = st.one_of(grammar(), st.sampled_from(["paper", "constant"]))
        else:
            good = _in_bounds(p)
        bad = HOSTILE_TEXT if p.name == "beta" else (_out_of_bounds(p) if not p.choices else st.text(max_size=8))
        out[p.name] = draw({"good": good, "bad": bad, "odd": ODD_VALUES}[draw(st.sampled_from(GOOD_BAD_ODD))])
    if draw(st.sampled_from(ONE_IN_TEN)):
        known = {p.name for p in scene.params}
        name = draw(st.one_of(st.sampled_from(["__class__", "", " gamma", "beta ", "Gamma", "q", "x0\n"]),
                              st.text(max_size=8)).filter(lambda n: n not in known))
        out[name] = draw(st.one_of(st.floats(), ODD_VALUES))
    return out


SANE = st.tuples(st.floats(1e-3, 2.0), st.floats(1.0, 2000.0)).map(lambda ht: ("sane", ht[0], ht[0] * ht[1]))
BAD_NUMBER = st.one_of(st.sampled_from([0.0, -0.0, 0, math.nan, math.inf, -math.inf]),
                       st.floats(max_value=-1e-300, allow_nan=False))
ODD_STEP = st.sampled_from([None, "0.1", "1", b"1", [0.1], 10 ** 400, 2 ** 1100, 1j, object])
HOSTILE_STEP_AND_HORIZON = st.sampled_from([
    st.tuples(BAD_NUMBER, st.floats(0.01, 10.0)).map(lambda p: ("bad h", *p)),
    st.tuples(st.floats(1e-3, 2.0), BAD_NUMBER).map(lambda p: ("bad T", *p)),
    st.tuples(BAD_NUMBER, BAD_NUMBER).map(lambda p: ("bad h and T", *p)),
    st.tuples(st.floats(5e-324, 1e-3), st.floats(1.01e8, 1e300)).map(lambda p: ("over cap", p[0], p[0] * p[1])),
    st.tuples(st.floats(5e-324, 1e-200), st.floats(1e100, 1e308)).map(lambda p: ("tiny h, huge T", *p)),
    st.tuples(st.floats(1e-3, 1e300), st.floats(1e-9, 0.999)).map(lambda p: ("h past T", p[0], p[0] * p[1])),
    st.tuples(ODD_STEP, st.floats(0.01, 10.0)).map(lambda p: ("odd h", *p)),
    st.tuples(st.floats(1e-3, 2.0), ODD_STEP).map(lambda p: ("odd T", *p)),
    # NumPy's numbers are numbers: taken like Python's
    st.tuples(st.sampled_from([np.float32(0.25), np.float64(0.5), np.int64(1)]),
              st.sampled_from([np.float32(2.0), np.int64(3)])).map(lambda p: ("numpy", *p)),
]).flatmap(lambda strategy: strategy)
STEP_AND_HORIZON = st.sampled_from([False, True]).flatmap(lambda sane: SANE if sane else HOSTILE_STEP_AND_HORIZON)
"""Half sane runs (at most 2000 steps), half step sizes and horizons that must be refused."""
ODD_THETA = st.sampled_from([math.nan, math.inf, -0.1, 1.5, -1e-300, 1 + 1e-15, "0.5", None, 0, 1, True])


@st.composite
def runs(draw):
    scene, method, theta = draw(st.sampled_from(CASES))
    if draw(st.sampled_from(ONE_IN_TEN)):
        theta = draw(ODD_THETA)
    values = draw(overrides(SCENES[scene]))
    kind, h, T = draw(STEP_AND_HORIZON)
    return scene, method, theta, values, kind, h, T


# ---------------------------------------------------------------- 1. Setup.make + simulate


def _check_trajectory(traj, h, T):
    steps = check_step(h, T)
    assert traj.steps == steps <= 2001
    assert len(traj.t) == traj.z.shape[0] == traj.pt.shape[0]
    assert traj.t[-1] == pytest.approx(steps * float(h), rel=1e-9)
    assert np.isfinite(traj.z).all() and np.isfinite(traj.pt).all()
    if not np.isfinite(traj.H).all():
        event("finite states, but H not finite at a record (beta(t) singular between stages)")


RUNNABLE = ("sane", "numpy")


@settings(max_examples=1500, deadline=2000, **SETTINGS)
@given(runs())
def test_setup_and_simulate_give_a_result_or_a_clear_error(run):
    scene, method, theta, values, kind, h, T = run
    start = time.perf_counter()
    status, setup = outcome(Setup.make, scene, method, values, theta)
    if status == "error":
        event(f"Setup.make: {type(setup).__name__}")
        assert_clear(str(setup))
        return
    assert setup.scene.name == scene and setup.method.name == method
    event(f"h, T: {kind}")
    status, traj = outcome(simulate, setup, h, T)
    if status == "ok":
        event("simulate: trajectory")
        assert kind in RUNNABLE, f"{kind} h = {h!r}, T = {T!r} gave a run"
        _check_trajectory(traj, h, T)
    else:
        event(f"simulate: {type(traj).__name__}")
        assert_clear(str(traj))
        if isinstance(traj, RunError):
            assert kind in RUNNABLE
            part = traj.partial
            assert part is not None and part.steps == traj.step and part.failure == str(traj)
            assert np.isfinite(part.z).all() and np.isfinite(part.pt).all()
        else:
            assert kind not in RUNNABLE, f"{kind} h = {h!r}, T = {T!r} refused: {traj}"
    assert time.perf_counter() - start < 2.0


# ---------------------------------------------------------------- 2. typed expressions cannot reach Python


def _attack_id(text):
    shown = text if len(text) <= 24 else f"{text[:12]}...{len(text)}chars"
    return repr(shown)


def _timed(fn, *args):
    """(outcome, seconds): the best of three calls, so that a load spike on a shared machine is not
    taken for a slow path (a slow path is slow every time)."""
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        result = outcome(fn, *args)
        best = min(best, time.perf_counter() - start)
    return result, best


@pytest.mark.parametrize("text", ATTACKS + sorted(HUGE), ids=_attack_id)
def test_expression_attacks_are_rejected_quickly_without_eval(text):
    with no_dynamic_code():
        (status, checked), elapsed_check = _timed(BETA.check, text)
        (made, setup), elapsed_make = _timed(Setup.make, "charged", "midpoint", {"beta": text})
        checked = checked if status == "error" else None
        ran = outcome(simulate, setup, 0.01, 2.0) if made == "ok" else None
    assert elapsed_check < 0.05 and elapsed_make < 0.05, (elapsed_check, elapsed_make)
    if text not in HUGE:
        assert checked is not None, f"{text[:80]!r} was accepted as beta(t)"
        assert made == "error" and isinstance(setup, InputError)
        assert_clear(str(checked))
        assert_clear(str(setup))
        return
    # a numeric expression finite at t = 0: either rejected, or its run stops with a clear error
    if made == "error":
        assert_clear(str(setup))
        return
    status, result = ran
    assert status == "error", f"{text!r} ran to T without leaving range"
    assert_clear(str(result))  # refused at the start (H not finite there) or a RunError naming the step
    assert re.search(r"overflow|Newton", str(result)), str(result)


@settings(max_examples=1000, deadline=1000, **SETTINGS)
@given(BETA_TEXT)
def test_random_beta_text_only_gives_expressions_or_one_line_errors_without_eval(text):
    with no_dynamic_code():
        start = time.perf_counter()
        status, value = outcome(BETA.check, text)
        elapsed = time.perf_counter() - start
    assert elapsed < 0.25  # generous: one measurement on a shared machine; the attack list checks 50 ms
    if status == "ok":
        event("accepted")
        assert value == text.strip()
    else:
        event("rejected")
        assert isinstance(value, InputError)
        assert_clear(str(value))
        assert str(value).startswith("beta(t)")


# ---------------------------------------------------------------- 3. the command line

COMMANDS = ("run", "workprecision", "report", "bench", "scenes", "methods")
CLI_METHODS = ("midpoint", "rk4", "theta", "boris", "exact", "gauss6")
JUNK = st.text(alphabet="abcdefgxyz019.-_=/ '\"\n\t\x00é", max_size=10).filter(
    lambda s: not (s.startswith("-") and "h" in s))


def mostly(good, *others):
    """`good` or one of `others`, good half the time or more (chosen by label: hypothesis favours the
    first branches of a one_of)."""
    return st.sampled_from([good] * max(2, len(others)) + list(others)).flatmap(lambda strategy: strategy)


H_TOKENS = mostly(st.floats(0.01, 0.5).map(repr),
                  st.sampled_from(["0", "-0", "-1", "nan", "NaN", "inf", "-inf", "infinity", "1e999", "1e-300",
                                   "5e-324", "1e308", "abc", "", " ", "0x10", "1_0", "\uff11", "--", "-"]), JUNK)
T_TOKENS = mostly(st.floats(0.01, 2.0).map(repr),
                  st.sampled_from(["0", "-1", "nan", "inf", "1e308", "1e9", "1e300", "abc", "", "2", "0.5"]), JUNK)
THETA_TOKENS = st.sampled_from(["0.3", "0.5", "1", "0", "1.5", "-0.1", "nan", "abc", ""])
INT_TOKENS = st.sampled_from(["16", "64", "0", "-1", "1e3", "abc", "99999999999", "99999999999999999999999", ""])
BUDGET_TOKENS = st.sampled_from(["1e-4", "0", "-1", "nan", "inf", "abc", ""])
PATH_TOKENS = st.sampled_from(["x.txt", "/nonexistent-dir/x.html", "/nonexistent-dir/x.csv", "", "x.HTML",
                               "x.html\x00.txt", "x.htm.bak", "/nonexistent-dir/"])
"""Output paths that are refused before any work (wrong suffix or no such folder)."""
PARAM_NAMES = sorted({p.name for s in SCENES.values() for p in s.params})
SET_TOKENS = st.one_of(
    st.builds(lambda n, v: f"{n}={v}", st.sampled_from(PARAM_NAMES),
              st.one_of(st.sampled_from([a for a in ATTACKS if len(a) <= 60]), T_TOKENS, grammar(2),
                        st.sampled_from(list(GAUGES) + ["paper", "constant"]))),
    st.sampled_from(["=", "=1", "gamma", "gamma=", "x=1", "beta=t.__class__"]), JUNK)


def _scene_token():
    return mostly(st.sampled_from(list(SCENES)), st.sampled_from(["paper", "", "Damped", "damped "]), JUNK)


def _method_token():
    return mostly(st.sampled_from(CLI_METHODS), st.sampled_from(["Midpoint", "", "exact "]), JUNK)


@st.composite
def options(draw, required, optional):
    """Flag/value pairs: all of `required` and some of `optional`, shuffled, each value drawn."""
    chosen = list(required) + draw(st.lists(st.sampled_from(list(optional)), unique=True, max_size=len(optional)))
    parts = []
    for flag in draw(st.permutations(chosen)):
        values = {**required, **optional}[flag]
        parts.append([flag] + (draw(values) if values is not None else []))
    argv = [token for part in parts for token in part]
    if draw(st.integers(0, 9)) == 0:
        argv.insert(draw(st.integers(0, len(argv))), draw(JUNK))
    return argv


def one(strategy):
    return strategy.map(lambda v: [v])


def some(strategy, size=2):
    return st.lists(strategy, min_size=1, max_size=size)


@st.composite
def cli_argv(draw, folder):
    command = draw(st.sampled_from(["run", "run", "run", "workprecision", "workprecision", "report", "bench",
                                    "scenes", "methods", "junk"]))
    if command == "run":
        return ["run", draw(_scene_token())] + draw(options(
            {"--h": one(H_TOKENS), "--T": one(T_TOKENS)},
            {"--method": one(_method_token()), "--theta": one(THETA_TOKENS),
             "--gauge": one(st.one_of(st.sampled_from(list(GAUGES)), JUNK)),
             "--transport-from": one(st.one_of(st.sampled_from(list(GAUGES)), JUNK)),
             "--set": one(SET_TOKENS), "--no-error": None, "--json": None}))
    if command == "workprecision":
        required = {"--methods": some(_method_token()), "--max-steps": one(INT_TOKENS),
                    "--budget": one(BUDGET_TOKENS), "--T": one(T_TOKENS)}
        optional = {"--h": some(H_TOKENS), "--theta": one(THETA_TOKENS), "--set": one(SET_TOKENS),
                    "--out": one(PATH_TOKENS)}
        if draw(st.booleans()):  # long horizons: always with small --horizons and an explicit --h
            required.pop("--T")
            required.update({"--long": None, "--h": one(H_TOKENS), "--horizons": some(T_TOKENS)})
            optional = {"--T": one(T_TOKENS), "--peers": None, "--theta": one(THETA_TOKENS),
                        "--set": one(SET_TOKENS)}
        return ["workprecision", draw(_scene_token())] + draw(options(required, optional))
    if command == "report":
        if draw(st.booleans()):  # a file that cannot be written: refused before any work, any target
            return ["report", draw(_scene_token())] + draw(options({"-o": one(PATH_TOKENS)},
                                                                   {"--h": one(H_TOKENS), "--T": one(T_TOKENS)}))
        target = draw(st.one_of(st.sampled_from(["damped", "charged"]), JUNK))
        return ["report", target] + draw(options(
            {"-o": st.just([f"{folder}/report.html"]), "--h": one(H_TOKENS), "--T": one(T_TOKENS)},
            {"--method": one(_method_token()), "--vs": one(_method_token()), "--theta": one(THETA_TOKENS),
             "--set": one(SET_TOKENS)}))
    if command == "bench":  # always refused: a bad --steps, or no scene/method pair
        bad = draw(st.sampled_from(["steps", "scene", "method"]))
        steps = draw(st.sampled_from(["0", "-1", "99999999999", "abc", "1e3", ""])) if bad == "steps" else "10"
        argv = ["bench", "--steps", steps]
        if bad == "scene":
            argv += ["--scenes", draw(JUNK.filter(lambda s: s not in SCENES))]
        elif bad == "method":
            argv += ["--scenes", "modulated", "--methods", "exact", "boris"]
        return argv
    if command == "junk":
        return draw(st.lists(JUNK, max_size=4))
    return [command] + draw(st.lists(JUNK, max_size=2))


def run_cli(argv):
    out, err = io.StringIO(), io.StringIO()
    code = main(argv, out=out, err=err)
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def cli_folder():
    """A writable folder for the reports the CLI test may write; the CLI's runs compiled beforehand."""
    folder = tempfile.mkdtemp(prefix="cosymp-hostile-")
    for scene in SCENES:
        for method in CLI_METHODS + ("theta-naive",):
            if METHODS[method].refusal(SCENES[scene]) is None:
                for extra in ([], ["--no-error"], ["--set", "beta=t"] if scene == "charged" else []):
                    run_cli(["run", scene, "--method", method, "--h", "0.1", "--T", "0.2"] + extra)
        run_cli(["workprecision", scene, "--methods", "midpoint", "rk4", "theta", "--T", "0.5", "--max-steps", "16",
                 "--budget", "1e-4"])
        run_cli(["workprecision", scene, "--long", "--methods", "midpoint", "rk4", "--h", "0.1", "--horizons", "1"])
    run_cli(["run", "charged", "--h", "0.1", "--T", "0.2", "--gauge", "landau", "--transport-from", "coulomb"])
    for scene in ("damped", "charged"):
        for method in CLI_METHODS:
            run_cli(["report", scene, "--method", method, "--vs", method, "--h", "0.1", "--T", "0.2",
                     "-o", f"{folder}/report.html"])
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.mark.slow
@settings(max_examples=1000, deadline=5000, **SETTINGS)
@given(data=st.data())
def test_cli_exits_0_2_or_3_with_one_line_on_error(cli_folder, data):
    argv = data.draw(cli_argv(cli_folder), label="argv")
    event(f"command: {argv[0] if argv and argv[0] in COMMANDS else '(junk)'}")
    code, out, err = run_cli(argv)
    event(f"exit {code}")
    assert code in (0, 2, 3), (code, err)
    assert "Traceback" not in err and "Traceback" not in out
    if code:
        assert err.startswith("cosymp: ") and err.endswith("\n"), err
        assert err.count("\n") == 1 and len(err.splitlines()) == 1, f"multi-line error: {err[:300]!r}"
        assert_clear(err[len("cosymp: "):-1])
    else:
        assert out


# ---------------------------------------------------------------- 4. the app session


@pytest.fixture(scope="module")
def session():
    """The app's Study class, and every scene's comparison loaded before the deadlines apply."""
    from app.study import Study

    for scene in SCENES:
        Study(scene=scene, **_good(scene))
    return Study


def _good(scene):
    h = SCENES[scene].h
    return {"method": "midpoint", "other": "rk4", "theta": 0.5, "h": h, "T": 20 * h, "values": {}}


BAD_STEP = st.one_of(BAD_NUMBER, st.sampled_from([2 ** 1100, 10 ** 400, "0.1", None, [0.1], 0.1j]))
"""Values that are not a usable h or T (a tiny positive T is usable: it rounds up to one step)."""


@st.composite
def hostile_actions(draw, scene):
    """(target, name, value): a bad value for one input of the study (or of its controls)."""
    s = SCENES[scene]
    names = {p.name for p in s.params}
    numeric = [p for p in s.params if not p.choices and p.name != "beta"]
    refused = [m for m in METHODS if METHODS[m].refusal(s)]
    kind = draw(st.sampled_from(["h", "T", "T", "values", "values", "inputs", "scene", "method", "theta"]))
    if kind == "h":
        return "study", "h", draw(st.one_of(BAD_STEP, st.sampled_from([5e-324, 1e-300, 1e-9])))
    if kind == "T":
        h = s.h
        return "study", "T", draw(st.one_of(BAD_STEP, st.sampled_from([h * 2_000_001, h * 1.5e8, 1e300]),
                                            st.floats(h * 2.1e6, 1e308)))
    if kind == "theta":
        return "study", "theta", draw(ODD_THETA.filter(lambda v: not (isinstance(v, (int, float)) and 0 <= v <= 1)))
    if kind == "scene":
        return "study", "scene", draw(st.one_of(JUNK, st.sampled_from(["Damped", "paper", None, 1])).filter(
            lambda v: v not in SCENES))
    if kind == "method":
        bad = st.one_of(JUNK.filter(lambda v: v not in METHODS), st.sampled_from(refused or ["nosuch"]))
        return "study", draw(st.sampled_from(["method", "other"])), draw(bad)
    if kind == "inputs":
        p = draw(st.sampled_from(s.params))
        if p.choices:
            return "inputs", p.name, draw(JUNK.filter(lambda v: v not in p.choices))
        if p.name == "beta":
            return "inputs", p.name, draw(st.sampled_from([a for a in ATTACKS if a not in HUGE and len(a) < 600]))
        return "inputs", p.name, draw(st.one_of(_out_of_bounds(p), st.sampled_from([math.nan, math.inf, "1", None])))
    # values: a dict with at least one bad entry, or not a dict at all
    entries = {}
    if numeric and draw(st.booleans()):
        p = draw(st.sampled_from(numeric))
        entries[p.name] = draw(st.one_of(_out_of_bounds(p), ODD_VALUES.filter(_not_a_number)))
    elif scene == "charged" and draw(st.booleans()):
        entries["beta"] = draw(st.one_of(st.sampled_from([a for a in ATTACKS if a not in HUGE and len(a) < 600]),
                                         st.sampled_from([None, 1j, [1]])))
    else:
        entries[draw(JUNK.filter(lambda n: n not in names))] = draw(st.floats(0, 1))
    return "study", "values", draw(st.one_of(st.just(entries), st.sampled_from([None, [], "gamma=1", {1: 2}])))


def _not_a_number(v):
    """True for the odd values that Param.check cannot take as a finite number."""
    try:
        return not math.isfinite(float(v))
    except (TypeError, ValueError, OverflowError):
        return True


@contextlib.contextmanager
def posted(study):
    """The notes the study posts inside the block."""
    notes = []
    watcher = study.param.watch(lambda e: notes.append(e.new), "message")
    try:
        yield notes
    finally:
        study.param.unwatch(watcher)


def _same(a, b):
    return a is b or a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


@settings(max_examples=150, deadline=5000, **SETTINGS)
@given(data=st.data())
def test_app_session_keeps_the_last_good_results_and_says_what_to_change(session, data):
    scene = data.draw(st.sampled_from(list(SCENES)), label="scene")
    good_inputs = _good(scene)
    study = session(scene=scene, **good_inputs)
    good = study.results
    assert (good.scene, good.h, good.T) == (scene, good_inputs["h"], good_inputs["T"])
    for target, name, value in data.draw(st.lists(hostile_actions(scene), min_size=1, max_size=3), label="actions"):
        obj = study.inputs if target == "inputs" else study
        before = getattr(obj, name)
        with posted(study) as notes:
            try:
                setattr(obj, name, value)
            except (ValueError, TypeError) as err:
                # refused by param's own validation: the input keeps its value and nothing else changes
                event(f"{target}.{name}: refused by param")
                assert _same(getattr(obj, name), before), \
                    f"{target}.{name} = {value!r} was set, then raised {type(err).__name__}: {err}"
            else:
                if _same(before, value):  # an equal value (np.float32(0.1) == 0.1 in NumPy 2) is no change
                    event(f"{target}.{name}: equal value, no change")
                else:
                    event(f"{target}.{name}: error note")
                    assert notes and notes[-1] is not None and notes[-1].level == "error", \
                        f"{target}.{name} = {value!r}: no error note ({notes})"
                    assert_clear(notes[-1].text)
        assert study.results is good, f"{target}.{name} = {value!r} replaced the last good results"
    # a good input still computes
    again = {**good_inputs, "T": 10 * good_inputs["h"]}
    with posted(study) as notes:
        study.param.update(**again)
    assert not [n for n in notes if n is not None and n.level == "error"], notes
    assert study.results is not good
    assert (study.results.scene, study.results.h, study.results.T) == (scene, again["h"], again["T"])
    assert all(e.comparison is not None for e in study.results.entries)


# ---------------------------------------------------------------- minimal reproducers of what the above found


def _make(scene, method="midpoint", values=None, theta=None):
    return lambda: Setup.make(scene, method, values, theta)


REPRODUCERS = {
    "check_step tiny h, huge T (T/h overflows)": lambda: check_step(5e-324, 1.0),
    "check_step h=1e-300, T=1e10": lambda: check_step(1e-300, 1e10),
    "check_step huge int T": lambda: check_step(0.1, 2 ** 1100),
    "huge int parameter": _make("damped", values={"gamma": 10 ** 400}),
    "newline in beta(t)": _make("charged", values={"beta": "t\n+x"}),
    "newline in a number": _make("damped", values={"q0": "1\n2"}),
    "newline in a parameter name": _make("damped", values={"x\ny": 1.0}),
    "newline in a scene name": lambda: get_scene("a\nb"),
    "1e6-character beta(t)": _make("charged", values={"beta": "t+" * 500_000 + "t"}),
}


@pytest.mark.parametrize("name", REPRODUCERS)
def test_reproducer_gives_one_clear_line(name):
    with pytest.raises(InputError) as info:
        REPRODUCERS[name]()
    assert_clear(str(info.value))


@pytest.mark.parametrize(("label", "call"), [
    ("float32 h", lambda: check_step(np.float32(0.1), 1.0)),
    ("int64 T", lambda: check_step(0.1, np.int64(1))),
    ("theta as text", _make("damped", "theta", theta="0.5")),
    ("float32 theta", _make("damped", "theta", theta=np.float32(0.5))),
])
def test_finite_values_of_other_types_are_taken_or_refused_without_a_false_reason(label, call):
    """A finite h is not 'not a finite number', and 0.5 is not 'outside [0, 1]'."""
    try:
        call()
    except InputError as err:
        assert "not a finite number" not in str(err) and "outside [0, 1]" not in str(err), str(err)


@pytest.mark.parametrize("argv", [
    ["run", "damped", "--h", "1e-300", "--T", "1e10"],
    ["run", "modulated", "--h", "1e308", "--T", "1"],
], ids=" ".join)
def test_cli_extreme_steps_exit_with_one_line(argv):
    code, _out, err = run_cli(argv)
    assert code in (2, 3) and err.count("\n") == 1


def test_cli_single_huge_step_is_not_told_to_increase_h():
    """One step of h = 1e300 (T = 1 rounds up to one step): the reference's step cap must not advise
    'increase h or shorten T'."""
    code, _out, err = run_cli(["run", "kapitza", "--h", "1e300", "--T", "1"])
    assert code in (2, 3) and "increase h" not in err, err


def test_a_step_longer_than_the_horizon_is_refused_not_run_far_past_it():
    """T/h rounds up to one step: h = 1e5 to T = 1 ran to t = 1e5, and h = 1e308 was blamed on T."""
    for h in ("1e5", "1e308"):
        code, out, err = run_cli(["run", "decaying", "--h", h, "--T", "1"])
        assert code == 2 and not out and "longer than the horizon T = 1" in err and "choose h <= T or a longer T" in err, err
    assert check_step(1.0 + 1e-12, 1.0) == 1
    code, out, err = run_cli(["run", "decaying", "--h", "1.0000001", "--T", "1"])
    assert code == 2 and "h = 1.0000001 is longer than the horizon T = 1:" in err, "h as typed (it read 'h = 1', T = 1)"


def test_a_failure_in_the_first_step_is_not_blamed_on_a_zero_step():
    """The damped scene's first step of h = 1e20 overflows: asking whether the exact flow overflows
    by t = 0 ran it with h = 0 and printed 'h = 0.0 must be positive'."""
    code, _out, err = run_cli(["run", "damped", "--h", "1e20", "--T", "1e20"])
    assert code == 3 and "overflow in step 1 (from t = 0)" in err and "must be positive" not in err, err


def test_the_exact_reference_is_split_below_h_where_its_one_step_map_overflows():
    """gamma = 10, one midpoint step of h = 100: the exact flow's one-step map over 100 overflows
    (e^(gamma h) > 1.8e308) long before its state does, at gamma t = 709 (t = 70.9); split only down
    to h, the reference said it left floating point at t = 0."""
    code, _out, err = run_cli(["run", "damped", "--set", "gamma=10", "--h", "100", "--T", "100"])
    found = re.search(r"leaves floating-point range \(\|z\| > 1.8e308\) at t ≈ ([0-9.]+)", err)
    assert code == 3 and found and 70 < float(found[1]) < 75, err


def test_a_run_that_starts_out_of_range_is_refused_before_it_runs():
    """beta(t) = 1.7e308 parses, but H(z0, 0) overflows: refused up front with what to change."""
    setup = Setup.make("charged", "euler", {"beta": "1.7e308"})
    with pytest.raises(InputError) as info:
        simulate(setup, 1.0, 1.0)
    assert_clear(str(info.value))
    assert "H at the start" in str(info.value)


def test_app_tiny_h_is_an_error_note(session):
    study = session(scene="damped", **_good("damped"))
    good = study.results
    study.h = 5e-324
    assert study.results is good and study.message.level == "error"
