"""Tests for cosymp.expr: parsing, limits, exact derivatives, programs and the numba evaluator."""

import contextlib
import math
import random
import sys
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cosymp import expr as ex
from cosymp.expr import ExprError, evaluate, evaluate_many, parse, programs, zero_programs

TS = np.array([0.3, 0.7, 1.1, 1.9, 2.6])


@pytest.fixture(scope="module", autouse=True)
def compiled():
    """Compile the evaluator once so timings and hypothesis deadlines measure parsing only."""
    parse("sin(t)")(np.array([0.5]))


def test_value_matches_numpy():
    got = parse("0.05*(1+10*sin(2*t))")(1.3)
    want = 0.05 * (1 + 10 * np.sin(2 * 1.3))
    assert isinstance(got, float)
    assert got == pytest.approx(want, rel=1e-15, abs=0)


@pytest.mark.parametrize(
    ("text", "t", "want"),
    [
        ("2^3^2", 0.0, 512.0),
        ("-2^2", 0.0, -4.0),
        ("2^-1", 0.0, 0.5),
        ("1-2-3", 0.0, -4.0),
        ("8/2/2", 0.0, 2.0),
        ("2+3*4", 0.0, 14.0),
        ("(2+3)*4", 0.0, 20.0),
        ("-t^2", 3.0, -9.0),
        ("(-t)^2", 3.0, 9.0),
        ("2^-t", 2.0, 0.25),
        ("-t*2", 3.0, -6.0),
        ("t*-2", 3.0, -6.0),
        ("--t", 3.0, 3.0),
        ("+t", 3.0, 3.0),
        ("pi", 0.0, math.pi),
        ("1e-3", 0.0, 1e-3),
        ("2.5E+4", 0.0, 2.5e4),
        (".5", 0.0, 0.5),
        ("5.", 0.0, 5.0),
        (" \t t  *\n2 ", 1.5, 3.0),
        ("sqrt(t)^2", 4.0, 4.0),
        ("exp(log(t))", 2.0, 2.0),
        ("tanh(0)+tan(0)+cos(0)", 0.0, 1.0),
    ],
)
def test_precedence_and_literals(text, t, want):
    assert parse(text, check_finite=False)(t) == pytest.approx(want, rel=1e-15)


@pytest.mark.parametrize("text", ["2t", "2 t", "t(1)", "(t)(t)", "2sin(t)", "t pi", "sin(t)cos(t)", "2 3"])
def test_implicit_multiplication_rejected(text):
    with pytest.raises(ExprError, match="missing operator"):
        parse(text)


def test_implicit_multiplication_message():
    with pytest.raises(ExprError) as info:
        parse("2t")
    assert str(info.value) == "missing operator between '2' and 't' at position 1: write 2*t"


def _sec2(x):
    return 1 / np.cos(x) ** 2


def _sqrt_log(t):
    s = np.sin(t)
    L = np.log(2 + s)
    L1 = np.cos(t) / (2 + s)
    L2 = (-2 * s - 1) / (2 + s) ** 2
    return np.sqrt(L), L1 / (2 * np.sqrt(L)), L2 / (2 * np.sqrt(L)) - L1**2 / (4 * L**1.5)


def _quotient(t):
    v = 2 + t**2
    return (
        (1 + t) / v,
        (2 - 2 * t - t**2) / v**2,
        ((-2 - 2 * t) * v - 4 * t * (2 - 2 * t - t**2)) / v**3,
    )


DERIVATIVES = {
    "3*t^4 - 2*t^3 + t - 7": lambda t: (
        3 * t**4 - 2 * t**3 + t - 7,
        12 * t**3 - 6 * t**2 + 1,
        36 * t**2 - 12 * t,
    ),
    "sin(2*t)": lambda t: (np.sin(2 * t), 2 * np.cos(2 * t), -4 * np.sin(2 * t)),
    "cos(t^2)": lambda t: (
        np.cos(t**2),
        -2 * t * np.sin(t**2),
        -2 * np.sin(t**2) - 4 * t**2 * np.cos(t**2),
    ),
    "tan(t/3)": lambda t: (np.tan(t / 3), _sec2(t / 3) / 3, 2 / 9 * _sec2(t / 3) * np.tan(t / 3)),
    "exp(-t/2)": lambda t: (np.exp(-t / 2), -np.exp(-t / 2) / 2, np.exp(-t / 2) / 4),
    "log(1+t^2)": lambda t: (np.log(1 + t**2), 2 * t / (1 + t**2), (2 - 2 * t**2) / (1 + t**2) ** 2),
    "sqrt(1+t)": lambda t: (np.sqrt(1 + t), 0.5 / np.sqrt(1 + t), -0.25 / (1 + t) ** 1.5),
    "tanh(3*t)": lambda t: (
        np.tanh(3 * t),
        3 * (1 - np.tanh(3 * t) ** 2),
        -18 * np.tanh(3 * t) * (1 - np.tanh(3 * t) ** 2),
    ),
    "(1+t)/(2+t^2)": _quotient,
    "t^t": lambda t: (t**t, t**t * (np.log(t) + 1), t**t * ((np.log(t) + 1) ** 2 + 1 / t)),
    "2^t": lambda t: (2**t, np.log(2) * 2**t, np.log(2) ** 2 * 2**t),
    "t^2.5": lambda t: (t**2.5, 2.5 * t**1.5, 3.75 * t**0.5),
    "1/t": lambda t: (1 / t, -1 / t**2, 2 / t**3),
    "exp(sin(t))": lambda t: (
        np.exp(np.sin(t)),
        np.cos(t) * np.exp(np.sin(t)),
        (np.cos(t) ** 2 - np.sin(t)) * np.exp(np.sin(t)),
    ),
    "sin(t)^2 + cos(t)^2": lambda t: (np.ones_like(t), 0 * t, 0 * t),
    "pi*t^2": lambda t: (np.pi * t**2, 2 * np.pi * t, 2 * np.pi + 0 * t),
    "-t^3": lambda t: (-(t**3), -3 * t**2, -6 * t),
    "sqrt(log(2+sin(t)))": _sqrt_log,
    "0.05*(1+10*sin(2*t))": lambda t: (0.05 * (1 + 10 * np.sin(2 * t)), np.cos(2 * t), -2 * np.sin(2 * t)),
}


@pytest.mark.parametrize("text", DERIVATIVES)
def test_exact_derivatives(text):
    e = parse(text, check_finite=False)
    d1 = e.derivative()
    d2 = d1.derivative()
    for got, want in zip((e(TS), d1(TS), d2(TS)), DERIVATIVES[text](TS), strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize(
    ("text", "derivative"),
    [
        ("t^2", "2*t"),
        ("3*t + 0*sin(t)", "3"),
        ("t^1 + t^0", "1"),
        ("5", "0"),
        ("2*(3*t)", "6"),
        ("t^t", "t^t*(log(t)+1)"),
        ("sin(2*t)", "2*cos(2*t)"),
        ("exp(t)", "exp(t)"),
        ("1 - t", "-1"),
        ("t/4", "0.25"),
    ],
)
def test_derivative_is_simplified(text, derivative):
    assert parse(text, check_finite=False).derivative().text == derivative


class Jet:
    """Value with first and second derivative, propagated by Taylor arithmetic."""

    def __init__(self, v, d=0.0, dd=0.0):
        self.v, self.d, self.dd = v, d, dd

    @staticmethod
    def lift(x):
        return x if isinstance(x, Jet) else Jet(x)

    def apply(self, f, f1, f2):
        return Jet(f, f1 * self.d, f2 * self.d**2 + f1 * self.dd)

    def __add__(self, other):
        o = Jet.lift(other)
        return Jet(self.v + o.v, self.d + o.d, self.dd + o.dd)

    __radd__ = __add__

    def __neg__(self):
        return Jet(-self.v, -self.d, -self.dd)

    def __sub__(self, other):
        return self + -Jet.lift(other)

    def __rsub__(self, other):
        return Jet.lift(other) - self

    def __mul__(self, other):
        o = Jet.lift(other)
        return Jet(
            self.v * o.v, self.d * o.v + self.v * o.d, self.dd * o.v + 2 * self.d * o.d + self.v * o.dd
        )

    __rmul__ = __mul__

    def __truediv__(self, other):
        o = Jet.lift(other)
        q = self.v / o.v
        q1 = (self.d - q * o.d) / o.v
        return Jet(q, q1, (self.dd - 2 * q1 * o.d - q * o.dd) / o.v)

    def __rtruediv__(self, other):
        return Jet.lift(other) / self

    def __pow__(self, other):
        if isinstance(other, Jet):
            return JET.exp(other * JET.log(self))
        return self.apply(
            self.v**other, other * self.v ** (other - 1), other * (other - 1) * self.v ** (other - 2)
        )

    def __rpow__(self, base):
        return JET.exp(self * math.log(base))


def _jet_function(f, f1, f2):
    def apply(u):
        u = Jet.lift(u)
        return u.apply(f(u.v), f1(u.v), f2(u.v))

    return staticmethod(apply)


class JET:
    """Functions on jets, named like numpy's."""

    sin = _jet_function(math.sin, math.cos, lambda x: -math.sin(x))
    cos = _jet_function(math.cos, lambda x: -math.sin(x), lambda x: -math.cos(x))
    tan = _jet_function(
        math.tan, lambda x: 1 / math.cos(x) ** 2, lambda x: 2 * math.tan(x) / math.cos(x) ** 2
    )
    exp = _jet_function(math.exp, math.exp, math.exp)
    log = _jet_function(math.log, lambda x: 1 / x, lambda x: -1 / x**2)
    sqrt = _jet_function(math.sqrt, lambda x: 0.5 / math.sqrt(x), lambda x: -0.25 / x**1.5)
    tanh = _jet_function(
        math.tanh, lambda x: 1 - math.tanh(x) ** 2, lambda x: -2 * math.tanh(x) * (1 - math.tanh(x) ** 2)
    )


SMOOTH_FORMS = [
    (2, "({0} + {1})", lambda a, b, m: a + b),
    (2, "({0} - {1})", lambda a, b, m: a - b),
    (2, "({0})*({1})", lambda a, b, m: a * b),
    (2, "({0})/(2 + sin({1}))", lambda a, b, m: a / (2 + m.sin(b))),
    (2, "(1.5 + sin({0}))^cos({1})", lambda a, b, m: (1.5 + m.sin(a)) ** m.cos(b)),
    (1, "sin({0})", lambda a, m: m.sin(a)),
    (1, "cos({0})", lambda a, m: m.cos(a)),
    (1, "tanh({0})", lambda a, m: m.tanh(a)),
    (1, "exp(sin({0}))", lambda a, m: m.exp(m.sin(a))),
    (1, "log(2 + cos({0}))", lambda a, m: m.log(2 + m.cos(a))),
    (1, "sqrt(1 + ({0})^2)", lambda a, m: m.sqrt(1 + a**2)),
    (1, "tan(sin({0})/2)", lambda a, m: m.tan(m.sin(a) / 2)),
    (1, "({0})^3", lambda a, m: a**3),
    (1, "-({0})", lambda a, m: -a),
    (1, "2^sin({0})", lambda a, m: 2 ** m.sin(a)),
]


def _smooth_expression(rng, depth):
    """(text, f) for a random expression smooth on the real line; f(x, m) evaluates it with functions m."""
    if depth == 0 or rng.random() < 0.2:
        if rng.random() < 0.6:
            return "t", lambda x, m: x
        c = rng.choice([0.5, 1.25, 3.0, 0.1])
        return repr(c), lambda x, m: c
    arity, template, fn = rng.choice(SMOOTH_FORMS)
    parts = [_smooth_expression(rng, depth - 1) for _ in range(arity)]
    text = template.format(*(p[0] for p in parts))
    return text, lambda x, m: fn(*(p[1](x, m) for p in parts), m)


@pytest.mark.parametrize("seed", range(40))
def test_random_derivatives_match_taylor_arithmetic_and_complex_step(seed):
    text, f = _smooth_expression(random.Random(seed), 4)
    e = parse(text, check_finite=False)
    d1 = e.derivative()
    d2 = d1.derivative()
    h = 1e-30
    for t in (-0.8, 0.3, 1.7):
        jet = Jet.lift(f(Jet(t, 1.0, 0.0), JET))
        step = f(complex(t, h), np).imag / h
        scale = 1 + abs(jet.v) + abs(jet.d) + abs(jet.dd)
        assert abs(e(t) - jet.v) <= 1e-12 * scale, text
        assert abs(d1(t) - jet.d) <= 1e-12 * scale, text
        assert abs(d1(t) - step) <= 1e-12 * scale, text
        assert abs(d2(t) - jet.dd) <= 1e-12 * scale, text


ROUND_TRIP = [
    "0.05*(1+10*sin(2*t))",
    "-t^2",
    "(-t)^2",
    "2^-t",
    "t^t",
    "2^3^2",
    "(2^3)^2",
    "1-(2-t)",
    "1-2-t",
    "8/(2/t)",
    "-(-t)",
    "--t",
    "t*-3",
    "-(t*3)",
    "(-t)*3",
    "1e-5*t + 1.5e+20",
    "pi*sin(pi*t)/(1+t^2)^1.5",
    "sqrt(1+tanh(t))^-0.5 - exp(-t/3)*log(2+cos(t))",
]


@pytest.mark.parametrize("text", ROUND_TRIP)
def test_text_round_trip(text):
    e = parse(text, check_finite=False)
    ts = np.linspace(-2.0, 3.0, 11)
    for current in (e, e.derivative(), e.derivative().derivative()):
        if len(current.text) <= ex.MAX_LENGTH:
            again = parse(current.text, check_finite=False)
            np.testing.assert_array_equal(again(ts), current(ts))
            assert again.text == current.text
    assert len(e.text) <= len(text)


@pytest.mark.parametrize(
    ("text", "normalized"),
    [
        (" 0.05 * ( 1 + 10*sin( 2*t ) ) ", "0.05*(1+10*sin(2*t))"),
        ("2^(-t)", "2^-t"),
        ("((t))+(+t)", "t+t"),
        ("(t*t)*t", "t*t*t"),
        ("t*(t*t)", "t*(t*t)"),
        ("(1-t)-(1-t)", "1-t-(1-t)"),
        ("(-2)^2", "(-2)^2"),
        ("-(2^2)", "-2^2"),
        ("(-t)*(-t)", "-t*-t"),
        ("2.50E+4", "25000"),
        (".5", ".5"),
        ("1.0e-5", "1e-05"),
    ],
)
def test_normalized_text(text, normalized):
    assert parse(text).text == normalized


@pytest.mark.parametrize(
    ("text", "latex"),
    [
        ("sin(2*t)", r"\sin(2 t)"),
        ("t^2", "t^{2}"),
        ("(1+t)/(2*t)", r"\frac{1 + t}{2 t}"),
        ("sqrt(1+t)", r"\sqrt{1 + t}"),
        ("log(t)*pi", r"\ln(t) \pi"),
        ("(t/2)^3", r"\left(\frac{t}{2}\right)^{3}"),
        ("2*3", r"2 \cdot 3"),
        ("-(t+1)", r"-\left(t + 1\right)"),
        ("1e-5*t", r"1 \cdot 10^{-5} t"),
    ],
)
def test_latex(text, latex):
    assert parse(text, check_finite=False).latex() == latex


REJECTED = [
    ("__import__('os')", "unknown name '__import__'"),
    ("t.__class__", "'.' at position 1"),
    ("().__class__.__bases__", "'.' at position 2"),
    ("x", "unknown name 'x' at position 0: only t, pi and sin cos tan exp log sqrt tanh are allowed"),
    ("t**2", "'**'"),
    ("'a'", "strings are not allowed"),
    ('"a"', "strings are not allowed"),
    ("lambda: 0", "unknown name 'lambda'"),
    ("sin(t, 2)", "','"),
    ("sin t", "needs parentheses"),
    ("exp", "needs parentheses"),
    ("1e999", "must be finite"),
    ("(" * (ex.MAX_DEPTH + 1) + "t" + ")" * (ex.MAX_DEPTH + 1), "nested too deeply"),
    ("sin(" * (ex.MAX_DEPTH + 1) + "t" + ")" * (ex.MAX_DEPTH + 1), "nested too deeply"),
    ("-" * (ex.MAX_DEPTH + 1) + "t", "nested too deeply"),
    ("2^" * (ex.MAX_DEPTH + 1) + "t", "nested too deeply"),
    ("(" * 10_000, "too long"),
    ("t+" * 5_000, "too long"),
    ("+".join(["1"] * 201), "too large"),
    ("", "empty expression"),
    ("  \t\n ", "empty expression"),
    ("t^", "operand is missing"),
    ("t + * 2", "unexpected '*'"),
    ("(t", "unbalanced parenthesis"),
    ("t)", "unbalanced parenthesis"),
    ("()", "empty '()'"),
    ("sin()", "empty 'sin()'"),
    ("t[0]", "brackets"),
    ("{t}", "brackets"),
    ("t;1", "';'"),
    ("t = 1", "unexpected character '='"),
    ("t//2", "unexpected '/'"),
    ("t % 2", "unexpected character '%'"),
    ("1.2.3", "malformed number"),
    ("2e", "malformed number"),
    ("1e+", "malformed number"),
    (".", "'.' at position 0"),
    ("T", "unknown name 'T'"),
    ("e", "unknown name 'e'"),
    ("sint", "unknown name 'sint'"),
    ("t\x00", "unexpected character"),
    ("t\u2028", "unexpected character"),
    ("t²", "unexpected character"),
    ("\u0661", "unexpected character"),
    ("log(t)", "beta(t) = log(t) is not finite at t = 0"),
    ("1/t", "not finite at t = 0"),
    ("sqrt(t)", "first derivative"),
    ("t^1.5", "second derivative"),
    ("/".join(["(1+t)"] * 80), "too complex"),
]


@pytest.mark.parametrize(("text", "message"), REJECTED)
def test_rejected_with_one_line_message(text, message):
    with pytest.raises(ExprError) as info:
        parse(text)
    assert message in str(info.value)
    assert len(str(info.value).splitlines()) == 1
    assert _largest_program(text) <= ex.MAX_PROGRAM


def test_error_type():
    assert issubclass(ExprError, ValueError)
    with pytest.raises(ExprError, match="must be text"):
        parse(b"t")


def test_limits_are_inclusive():
    deepest = "(" * ex.MAX_DEPTH + "t" + ")" * ex.MAX_DEPTH
    assert parse(deepest)(2.0) == 2.0
    assert parse("-" * ex.MAX_DEPTH + "t")(2.0) == 2.0
    assert parse("+".join(["1"] * 200))(0.0) == 200.0
    longest = "t" + " " * (ex.MAX_LENGTH - 1)
    assert parse(longest)(3.0) == 3.0
    with pytest.raises(ExprError, match="too long"):
        parse(longest + " ")


def test_no_deep_recursion():
    """Deepest allowed inputs and long chains parse and differentiate well within a small recursion budget."""
    texts = [
        "(" * ex.MAX_DEPTH + "t" + ")" * ex.MAX_DEPTH,
        "sin(" * 20 + "t" + ")" * 20,
        "*".join(["t"] * 100),
        "-".join(["t"] * 200),
        "/".join(["t"] * 120),
    ]
    depth = 0
    frame = sys._getframe()
    while frame is not None:
        depth += 1
        frame = frame.f_back
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(depth + 350)
    try:
        for text in texts:
            e = parse(text, check_finite=False)
            e.derivative().latex()
    finally:
        sys.setrecursionlimit(limit)


def test_domain_errors_give_nan_or_inf():
    assert math.isnan(parse("log(t)", check_finite=False)(-1.0))
    assert math.isnan(parse("sqrt(t)", check_finite=False)(-1.0))
    assert parse("1/t", check_finite=False)(0.0) == math.inf
    assert parse("t^-1", check_finite=False)(0.0) == math.inf
    assert math.isnan(parse("(t-9)^(1/3)", check_finite=False)(1.0))
    assert parse("exp(t)", check_finite=False)(1e3) == math.inf


@pytest.mark.parametrize("text, pole", [
    ("1/(t-5)", 5.0),  # sampled exactly
    ("1/(t-5.001)", 5.001),  # between the samples: a sign change of the divisor, then bisection
    ("1/(t-5)^2", 5.0),  # the divisor keeps its sign: its base changes it
    ("(t-5)^(-3)", 5.0),
    ("tan(t)", math.pi / 2),
    ("1/sin(t+0.1)", math.pi - 0.1),
    ("1/((t-7)*(t-3))", 3.0),  # the first of two
    ("t/(t^2-16)", 4.0),
    ("1/(sqrt(t+1)-3)", 8.0),
    ("log(10-t)", 10.0),  # not finite from there on
    ("sqrt(12-t)", 12.0),  # its derivative divides by 0 at 12
    ("exp(-t/5)*sin(2*pi*t)", None),
    ("1/(2+sin(t))", None),
    ("1/(1+t^2)", None),
    ("0.5*(1+0.3*cos(3*t))", None),
])
def test_singularity_is_the_first_pole_or_end_of_the_domain_in_the_range(text, pole):
    """A typed beta(t) runs over [0, T]: its first singular point there, to round-off, or None."""
    found = parse(text).singularity(0.0, 20.0)
    if pole is None:
        assert found is None
    else:
        assert found == pytest.approx(pole, rel=1e-12, abs=1e-12)
    assert parse(text).singularity(0.0, 1.0) is None  # every pole here lies beyond t = 1


def test_array_calls_keep_shape_and_match_scalars():
    e = parse("sin(t)*exp(-t^2)")
    ts = np.linspace(-2, 2, 12).reshape(3, 4)
    values = e(ts)
    assert values.shape == (3, 4)
    np.testing.assert_array_equal(values.ravel(), [e(t) for t in ts.ravel()])
    assert e(np.float32(0.5)) == e(0.5)
    assert e([0.5])[0] == e(0.5)


def test_program_and_evaluators():
    e = parse("0.5*t + 2")
    ops, args = e.program()
    assert ops.dtype == np.int64 and args.dtype == np.float64
    assert ops.tolist() == [ex.OP_CONST, ex.OP_T, ex.OP_MUL, ex.OP_CONST, ex.OP_ADD]
    assert args.tolist() == [0.5, 0.0, 0.0, 2.0, 0.0]
    assert evaluate(ops, args, 4.0) == 4.0
    ts = np.array([0.0, 1.0, 2.0])
    out = np.empty(3)
    assert evaluate_many(ops, args, ts, out) is out
    np.testing.assert_array_equal(out, [2.0, 2.5, 3.0])
    ops[0] = ex.OP_END
    assert e(4.0) == 4.0


def test_programs_padding():
    e = parse("sin(2*t)*exp(-t/3)")
    ops, args = programs(e)
    rows = [e, e.derivative(), e.derivative().derivative()]
    length = max(row.program()[0].size for row in rows)
    assert ops.shape == args.shape == (3, length)
    assert ops.dtype == np.int64 and args.dtype == np.float64
    for k, row in enumerate(rows):
        row_ops, row_args = row.program()
        assert (ops[k, row_ops.size :] == ex.OP_END).all()
        np.testing.assert_array_equal(ops[k, : row_ops.size], row_ops)
        for t in TS:
            assert evaluate(ops[k], args[k], t) == evaluate(row_ops, row_args, t) == row(t)
    ops1, _ = programs(e, orders=1)
    assert ops1.shape == (1, e.program()[0].size)
    assert programs(e, orders=5)[0].shape[0] == 5
    with pytest.raises(ValueError):
        programs(e, orders=0)


def test_zero_programs():
    ops, args = zero_programs()
    assert ops.shape == args.shape == (3, 1)
    assert ops.dtype == np.int64 and args.dtype == np.float64
    assert all(evaluate(ops[k], args[k], 1.7) == 0.0 for k in range(3))
    assert zero_programs(2)[0].shape == (2, 1)


def test_expr_is_immutable():
    e = parse("t")
    with pytest.raises(AttributeError):
        e.text = "1"
    assert repr(e) == "Expr('t')" and str(e) == "t"


JUNK = "0123456789.eE+-*/^() \t\ntpisncoxglqrh_,;'\"[]{}!@#$%&|~`<>?:=\\²é\x00"


@settings(max_examples=400, deadline=500, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(alphabet=JUNK, max_size=600))
def test_random_text_only_raises_expr_error(text):
    try:
        e = parse(text)
    except ExprError as err:
        assert len(str(err).splitlines()) == 1
    else:
        assert math.isfinite(e(0.0))
        assert len(e.text) <= len(text)
        assert parse(e.text).text == e.text
    assert _largest_program(text) <= ex.MAX_PROGRAM


def _largest_program(text):
    """Length of the longest RPN program parse(text) builds: its work is bounded, measured without a clock."""
    sizes = [0]
    build = ex._program

    def recorded(root):
        ops, args = build(root)
        sizes.append(ops.size)
        return ops, args

    with mock.patch.object(ex, "_program", recorded), contextlib.suppress(ExprError):
        parse(text)
    return max(sizes)


@settings(max_examples=300, deadline=500, suppress_health_check=[HealthCheck.too_slow])
@given(st.text(alphabet="0123456789.+-*/^() tpisncoxglqrh", min_size=1, max_size=80))
def test_random_grammar_text_only_raises_expr_error(text):
    try:
        parse(text)
    except ExprError as err:
        assert len(str(err).splitlines()) == 1


NUMBERS = st.one_of(
    st.integers(0, 10**6).map(str),
    st.floats(0, 100, allow_nan=False).map(lambda x: repr(round(x, 4))),
    st.sampled_from(["1e-300", "5e-324", "1.7e308", ".5", "2.5E+4"]),
)


@st.composite
def trees(draw, depth=4):
    """Text of a random well-formed expression, explicitly parenthesized."""
    if depth == 0 or draw(st.integers(0, 3)) == 0:
        return draw(st.one_of(st.sampled_from(["t", "pi"]), NUMBERS))
    kind = draw(st.sampled_from(["binary", "unary", "call"]))
    if kind == "binary":
        op = draw(st.sampled_from("+-*/^"))
        return f"({draw(trees(depth - 1))}){op}({draw(trees(depth - 1))})"
    if kind == "unary":
        return draw(st.sampled_from("+-")) + f"({draw(trees(depth - 1))})"
    return f"{draw(st.sampled_from(ex.FUNCTIONS))}({draw(trees(depth - 1))})"


@settings(max_examples=300, deadline=1000, suppress_health_check=[HealthCheck.too_slow])
@given(trees())
def test_random_trees_parse_and_evaluate(text):
    e = parse(text, check_finite=False)
    ts = np.array([0.0, 0.7, -1.3, 1e3])
    values = e(ts)
    assert values.shape == ts.shape
    again = parse(e.text, check_finite=False)
    assert again.text == e.text
    np.testing.assert_array_equal(again(ts), values)
    try:
        d2 = e.derivative().derivative()
    except ExprError as err:
        assert "too complex" in str(err)
    else:
        assert d2(ts).shape == ts.shape
        ops, args = programs(e)
        assert ops.shape[0] == 3
        np.testing.assert_array_equal([evaluate(ops[2], args[2], t) for t in ts], d2(ts))
    try:
        parse(text)
    except ExprError as err:
        assert "not finite at t = 0" in str(err) or "too complex" in str(err)
