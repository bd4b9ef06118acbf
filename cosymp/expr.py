"""Safe parser, symbolic derivative and numba evaluator for expressions of t.

User text is tokenized and parsed by hand; it never reaches eval, exec or
compile. An expression becomes a tree of tuples (``('add', a, b)``,
``('sin', a)``, ``('num', 2.0)``, ``('t',)``, ``('pi',)``) that is turned into
an RPN program of integer opcodes for :func:`evaluate`.
"""

import math

import numba
import numpy as np

from cosymp.errors import InputError

MAX_LENGTH = 500
MAX_DEPTH = 40
MAX_NODES = 400
MAX_PROGRAM = 20_000
SINGULAR_SAMPLES = 1 << 13  # intervals of [t0, t1] in which Expr.singularity looks for a divisor's sign change
BISECTIONS = 60

OP_END = 0
OP_CONST = 1
OP_T = 2
OP_ADD = 3
OP_SUB = 4
OP_MUL = 5
OP_DIV = 6
OP_POW = 7
OP_NEG = 8
OP_SIN = 9
OP_COS = 10
OP_TAN = 11
OP_EXP = 12
OP_LOG = 13
OP_SQRT = 14
OP_TANH = 15

FUNCTIONS = ("sin", "cos", "tan", "exp", "log", "sqrt", "tanh")

_BINARY = {"add": OP_ADD, "sub": OP_SUB, "mul": OP_MUL, "div": OP_DIV, "pow": OP_POW}
_UNARY = {
    "neg": OP_NEG,
    "sin": OP_SIN,
    "cos": OP_COS,
    "tan": OP_TAN,
    "exp": OP_EXP,
    "log": OP_LOG,
    "sqrt": OP_SQRT,
    "tanh": OP_TANH,
}
_SYMBOLS = {"add": "+", "sub": "-", "mul": "*", "div": "/"}
_PREC = {"add": 1, "sub": 1, "mul": 2, "div": 2}
_ATOM = 5

_WHITESPACE = frozenset(" \t\n\r\f\v")
_DIGITS = frozenset("0123456789")
_NAME_START = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ_")
_NAME_CHARS = _NAME_START | _DIGITS
_OPERATORS = frozenset("+-*/^")
_ALLOWED = "only t, pi and " + " ".join(FUNCTIONS) + " are allowed"

_ZERO = ("num", 0.0)
_ONE = ("num", 1.0)
_TWO = ("num", 2.0)


class ExprError(InputError):
    """An expression that cannot be used; the message says what to change."""


def _num(value):
    return ("num", value + 0.0)


def _is_num(node, value=None):
    return node[0] == "num" and (value is None or node[1] == value)


def _same(a, b):
    return a is b or (a[0] in ("t", "pi") and a == b)


def _children(node):
    kind = node[0]
    if kind in _BINARY:
        return node[1:3]
    if kind in _UNARY:
        return node[1:2]
    return ()


def _fold(root, combine):
    """Apply ``combine(node, child_results)`` bottom-up, once per distinct node, without recursion."""
    memo = {}
    stack = [root]
    while stack:
        node = stack[-1]
        if id(node) in memo:
            stack.pop()
            continue
        kids = _children(node)
        pending = [kid for kid in kids if id(kid) not in memo]
        if pending:
            stack.extend(pending)
            continue
        stack.pop()
        memo[id(node)] = combine(node, [memo[id(kid)] for kid in kids])
    return memo[id(root)]


def _size(node, kids):
    return 1 + sum(kids)


# Tokenizer and parser.


def _tokenize(text):
    """Split text into (kind, text, position, value) tokens; kind is num, name, op, ( or )."""
    tokens = []
    depth = 0
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch in _WHITESPACE:
            i += 1
        elif ch in _DIGITS or ch == ".":
            i = _scan_number(text, i, tokens)
        elif ch in _NAME_START:
            j = i + 1
            while j < n and text[j] in _NAME_CHARS:
                j += 1
            name = text[i:j]
            if name not in ("t", "pi") and name not in FUNCTIONS:
                raise ExprError(f"unknown name {name!r} at position {i}: {_ALLOWED}")
            tokens.append(("name", name, i, None))
            i = j
        elif ch in _OPERATORS:
            if ch == "*" and text.startswith("*", i + 1):
                raise ExprError(f"'**' at position {i} is not supported: write powers with ^")
            tokens.append(("op", ch, i, None))
            i += 1
        elif ch == "(":
            depth += 1
            if depth > MAX_DEPTH:
                raise ExprError(
                    f"parentheses nested too deeply at position {i}: at most {MAX_DEPTH} levels are allowed"
                )
            tokens.append(("(", ch, i, None))
            i += 1
        elif ch == ")":
            depth -= 1
            if depth < 0:
                raise ExprError(f"unbalanced parenthesis: ')' at position {i} has no matching '('")
            tokens.append((")", ch, i, None))
            i += 1
        else:
            raise ExprError(_bad_character(ch, i))
    if depth:
        raise ExprError(f"unbalanced parenthesis: {depth} '(' not closed; add ')'")
    return tokens


def _bad_character(ch, i):
    if ch in "'\"":
        return f"strings are not allowed (quote at position {i}): write a formula in t"
    if ch in "[]{}":
        return f"brackets are not allowed (position {i}): group with ( and )"
    if ch == ",":
        return f"',' at position {i} is not allowed: functions take exactly one argument"
    if ch == ";":
        return f"';' at position {i} is not allowed: write a single expression"
    return f"unexpected character {ch!r} at position {i}: use numbers, t, pi, functions, + - * / ^ and ( )"


def _scan_number(text, i, tokens):
    n = len(text)
    j = i
    while j < n and text[j] in _DIGITS:
        j += 1
    if j < n and text[j] == ".":
        j += 1
        while j < n and text[j] in _DIGITS:
            j += 1
    if j == i + 1 and text[i] == ".":
        raise ExprError(
            f"'.' at position {i} is not allowed: no attribute access, and numbers need digits as in 0.5"
        )
    if j < n and text[j] in "eE" and not (j + 1 < n and text[j + 1] in _NAME_START):
        k = j + 1
        if k < n and text[k] in "+-":
            k += 1
        if not (k < n and text[k] in _DIGITS):
            raise ExprError(f"malformed number {text[i:k]!r} at position {i}: write an exponent like 1e-3")
        while k < n and text[k] in _DIGITS:
            k += 1
        j = k
    if j < n and (text[j] == "." or text[j] in _DIGITS):
        raise ExprError(
            f"malformed number {text[i : j + 1]!r} at position {i}: write numbers like 1.5 or 2e-3"
        )
    literal = text[i:j]
    value = float(literal)
    if not math.isfinite(value):
        raise ExprError(f"number {literal!r} at position {i} is too large: numbers must be finite")
    tokens.append(("num", literal, i, value))
    return j


def _starts_operand(token):
    return token[0] in ("num", "name", "(")


def _ends_operand(token):
    return token[0] in ("num", ")") or token[1] in ("t", "pi")


class _Parser:
    """Recursive descent over tokens with explicit depth and node limits."""

    def __init__(self, tokens):
        self.tokens = tokens
        self.i = 0
        self.depth = 0
        self.nodes = 0

    def peek(self):
        return self.tokens[self.i] if self.i < len(self.tokens) else None

    def peek_op(self, ops):
        token = self.peek()
        return token if token is not None and token[0] == "op" and token[1] in ops else None

    def node(self, *parts):
        self.nodes += 1
        if self.nodes > MAX_NODES:
            raise ExprError(
                f"expression too large: at most {MAX_NODES} numbers, names and operators are allowed"
            )
        return parts

    def enter(self, token):
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise ExprError(
                f"expression nested too deeply at position {token[2]}: at most {MAX_DEPTH} levels are allowed"
            )

    def parse(self):
        result = self.expression()
        if self.peek() is not None:
            raise self.unexpected()
        return result

    def expression(self):
        left = self.term()
        while token := self.peek_op("+-"):
            self.i += 1
            left = self.node("add" if token[1] == "+" else "sub", left, self.term())
        return left

    def term(self):
        left = self.unary()
        while token := self.peek_op("*/"):
            self.i += 1
            left = self.node("mul" if token[1] == "*" else "div", left, self.unary())
        return left

    def unary(self):
        token = self.peek_op("+-")
        if token is None:
            return self.power()
        self.i += 1
        self.enter(token)
        operand = self.unary()
        self.depth -= 1
        return operand if token[1] == "+" else self.node("neg", operand)

    def power(self):
        base = self.atom()
        token = self.peek_op("^")
        if token is None:
            return base
        self.i += 1
        self.enter(token)
        exponent = self.unary()
        self.depth -= 1
        return self.node("pow", base, exponent)

    def atom(self):
        token = self.peek()
        if token is None or not _starts_operand(token):
            raise self.unexpected()
        self.i += 1
        kind, text = token[0], token[1]
        if kind == "num":
            return self.node("num", token[3], text)
        if kind == "(":
            return self.group(token, "()")
        if text in ("t", "pi"):
            return self.node(text)
        opening = self.peek()
        if opening is None or opening[0] != "(":
            raise ExprError(f"function {text!r} at position {token[2]} needs parentheses: write {text}(...)")
        self.i += 1
        return self.node(text, self.group(opening, f"{text}()"))

    def group(self, opening, empty):
        self.enter(opening)
        closing = self.peek()
        if closing is not None and closing[0] == ")":
            raise ExprError(f"empty {empty!r} at position {opening[2]}: put an expression inside")
        inner = self.expression()
        closing = self.peek()
        if closing is None or closing[0] != ")":
            raise self.unexpected()
        self.i += 1
        self.depth -= 1
        return inner

    def unexpected(self):
        token = self.peek()
        previous = self.tokens[self.i - 1] if self.i else None
        if token is None:
            return ExprError(f"expression ends after {previous[1]!r}: an operand is missing")
        text, pos = token[1], token[2]
        if previous is not None and _ends_operand(previous) and _starts_operand(token):
            return ExprError(
                f"missing operator between {previous[1]!r} and {text!r} at position {pos}: "
                f"write {previous[1]}*{text}"
            )
        if token[0] == ")":
            return ExprError(f"unexpected ')' at position {pos}: an operand is missing before it")
        return ExprError(
            f"unexpected {text!r} at position {pos}: expected a number, t, pi, a function or '('"
        )


def parse(text, *, check_finite=True):
    """Parse text into an Expr; check_finite requires it and its first two derivatives finite at t = 0."""
    if not isinstance(text, str):
        raise ExprError(f"expression must be text, not {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise ExprError(f"expression too long ({len(text)} characters): at most {MAX_LENGTH} are allowed")
    tokens = _tokenize(text)
    if not tokens:
        raise ExprError("empty expression: write a formula in t, e.g. 0.1*sin(t)")
    expr = Expr(_Parser(tokens).parse())
    if check_finite:
        _check_finite(expr)
    return expr


def _check_finite(expr):
    labels = ("", "the first derivative of ", "the second derivative of ")
    current = expr
    for order, label in enumerate(labels):
        if order:
            current = current.derivative()
        value = evaluate(current._ops, current._args, 0.0)
        if not math.isfinite(value):
            raise ExprError(
                f"{label}beta(t) = {_short(expr.text)} is not finite at t = 0 (it is {value}): "
                "use a formula smooth at t = 0"
            )


# Simplifying constructors used by the derivative.


def _fold_num(function, *values):
    try:
        value = function(*values)
    except (ArithmeticError, ValueError):
        return None
    return _num(value) if math.isfinite(value) else None


def _neg(a):
    if _is_num(a):
        return _num(-a[1])
    if a[0] == "neg":
        return a[1]
    if a[0] == "sub":
        return ("sub", a[2], a[1])
    return ("neg", a)


def _add(a, b):
    if _is_num(a) and _is_num(b):
        return _fold_num(float.__add__, a[1], b[1]) or ("add", a, b)
    if _is_num(a, 0.0):
        return b
    if _is_num(b, 0.0):
        return a
    if b[0] == "neg":
        return _sub(a, b[1])
    if _is_num(b) and b[1] < 0:
        return ("sub", a, _num(-b[1]))
    if a[0] == "neg":
        return _sub(b, a[1])
    return ("add", a, b)


def _sub(a, b):
    if _is_num(a) and _is_num(b):
        return _fold_num(float.__sub__, a[1], b[1]) or ("sub", a, b)
    if _is_num(b, 0.0):
        return a
    if _is_num(a, 0.0):
        return _neg(b)
    if b[0] == "neg":
        return _add(a, b[1])
    if _is_num(b) and b[1] < 0:
        return ("add", a, _num(-b[1]))
    if _same(a, b):
        return _ZERO
    return ("sub", a, b)


def _mul(a, b):
    if _is_num(b) and not _is_num(a):
        a, b = b, a
    if _is_num(a):
        if _is_num(b):
            return _fold_num(float.__mul__, a[1], b[1]) or ("mul", a, b)
        if a[1] == 0.0:
            return _ZERO
        if a[1] == 1.0:
            return b
        if a[1] == -1.0:
            return _neg(b)
        if b[0] == "mul" and _is_num(b[1]):
            folded = _fold_num(float.__mul__, a[1], b[1][1])
            if folded is not None:
                return _mul(folded, b[2])
    elif b[0] == "mul" and _is_num(b[1]):
        return _mul(_mul(b[1], a), b[2])
    if a[0] == "neg":
        return _neg(_mul(a[1], b))
    if b[0] == "neg":
        return _neg(_mul(a, b[1]))
    return ("mul", a, b)


def _div(a, b):
    if _is_num(a) and _is_num(b):
        return _fold_num(float.__truediv__, a[1], b[1]) or ("div", a, b)
    if _is_num(a, 0.0):
        return _ZERO
    if _is_num(b, 1.0):
        return a
    if _same(a, b):
        return _ONE
    if a[0] == "neg":
        return _neg(_div(a[1], b))
    if b[0] == "neg" or (_is_num(b) and b[1] < 0):
        return _neg(_div(a, _neg(b)))
    return ("div", a, b)


def _pow(a, b):
    if _is_num(a) and _is_num(b):
        return _fold_num(math.pow, a[1], b[1]) or ("pow", a, b)
    if _is_num(b, 0.0) or _is_num(a, 1.0):
        return _ONE
    if _is_num(b, 1.0):
        return a
    return ("pow", a, b)


def _diff_node(node, d):
    """Derivative of node given the derivatives d of its children."""
    kind = node[0]
    if kind == "t":
        return _ONE
    if kind in ("num", "pi"):
        return _ZERO
    a = node[1]
    if kind == "add":
        return _add(d[0], d[1])
    if kind == "sub":
        return _sub(d[0], d[1])
    if kind == "neg":
        return _neg(d[0])
    if kind == "mul":
        return _add(_mul(d[0], node[2]), _mul(a, d[1]))
    if kind == "div":
        b = node[2]
        if _is_num(d[1], 0.0):
            return _div(d[0], b)
        return _div(_sub(_mul(d[0], b), _mul(a, d[1])), _pow(b, _TWO))
    if kind == "pow":
        b = node[2]
        if _is_num(d[1], 0.0):
            return _mul(_mul(b, _pow(a, _sub(b, _ONE))), d[0])
        inner = _add(_mul(d[1], ("log", a)), _div(_mul(b, d[0]), a))
        return _mul(node, inner)
    if kind == "sin":
        outer = ("cos", a)
    elif kind == "cos":
        outer = _neg(("sin", a))
    elif kind == "tan":
        outer = _div(_ONE, _pow(("cos", a), _TWO))
    elif kind == "exp":
        outer = node
    elif kind == "log":
        return _div(d[0], a)
    elif kind == "sqrt":
        return _div(d[0], _mul(_TWO, node))
    else:
        outer = _sub(_ONE, _pow(node, _TWO))
    return _mul(outer, d[0])


# Singularities.


def _divisors(root):
    """The distinct subtrees that divide somewhere in root: denominators, bases of negative
    constant powers, and the cosine of tan's argument."""
    found, seen, stack = [], set(), [root]
    while stack:
        node = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        kind = node[0]
        if kind == "div":
            found.append(node[2])
        elif kind == "pow" and _is_num(node[2]) and node[2][1] < 0:
            found.append(node[1])
        elif kind == "tan":
            found.append(("cos", node[1]))
        stack.extend(_children(node))
    return found


def _sign_carriers(node):
    """Subtrees that change sign at every zero of node: the factors of a product, the base of a
    positive constant power, the numerator of a quotient, the argument of a negation or a square
    root (whose zeros are node's, where node itself may keep its sign: (t - 5)^2), else node."""
    out, stack = [], [node]
    while stack:
        n = stack.pop()
        kind = n[0]
        if kind == "mul":
            stack.extend(n[1:3])
        elif kind in ("neg", "sqrt", "div") or (kind == "pow" and _is_num(n[2]) and n[2][1] > 0):
            stack.append(n[1])
        elif kind not in ("num", "pi", "exp"):
            out.append(n)
    return out


def _root(f, lo, hi, f_lo):
    """A zero of f between lo and hi, where f changes sign (f(lo) = f_lo), by bisection."""
    if f_lo == 0.0:
        return lo
    for _ in range(BISECTIONS):
        mid = 0.5 * (lo + hi)
        f_mid = f(mid)
        if f_mid == 0.0:
            return mid
        if (f_mid > 0.0) == (f_lo > 0.0):
            lo, f_lo = mid, f_mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


# Rendering.


def _short(text, limit=80):
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _number_text(value):
    if value.is_integer() and abs(value) < 1e16:
        return str(int(value))
    return repr(value)


def _text_node(node, kids):
    """(text, precedence) of node with only the parentheses the grammar needs.

    The text of a parsed expression is never longer or more deeply nested than the input,
    so it parses again within the limits.
    """
    kind = node[0]
    if kind == "num":
        text = _number_text(node[1])
        if len(node) > 2 and len(node[2]) < len(text):
            text = node[2]
        return text, (3 if node[1] < 0 else _ATOM)
    if kind in ("t", "pi"):
        return kind, _ATOM
    if kind == "neg":
        text, prec = kids[0]
        return "-" + (f"({text})" if prec < 3 else text), 3
    if kind in _UNARY:
        return f"{kind}({kids[0][0]})", _ATOM
    (left, lp), (right, rp) = kids
    if kind == "pow":
        left = f"({left})" if lp < _ATOM else left
        right = f"({right})" if rp < 3 else right
        return f"{left}^{right}", 4
    prec = _PREC[kind]
    left = f"({left})" if lp < prec else left
    right = f"({right})" if rp <= prec else right
    return f"{left}{_SYMBOLS[kind]}{right}", prec


def _latex_number(value):
    text = _number_text(value)
    if "e" not in text:
        return text, (3 if value < 0 else _ATOM)
    mantissa, exponent = text.split("e")
    return f"{mantissa} \\cdot 10^{{{int(exponent)}}}", 2


def _latex_node(node, kids):
    """(LaTeX, precedence) of node; a fraction has precedence 4.5: grouped, but not a valid base."""
    kind = node[0]
    if kind == "num":
        return _latex_number(node[1])
    if kind == "t":
        return "t", _ATOM
    if kind == "pi":
        return "\\pi", _ATOM
    if kind == "neg":
        text, prec = kids[0]
        return "-" + (f"\\left({text}\\right)" if prec <= 3 else text), 3
    if kind == "sqrt":
        return f"\\sqrt{{{kids[0][0]}}}", _ATOM
    if kind in _UNARY:
        name = "ln" if kind == "log" else kind
        return f"\\{name}({kids[0][0]})", _ATOM
    (left, lp), (right, rp) = kids
    if kind == "div":
        return f"\\frac{{{left}}}{{{right}}}", 4.5
    if kind == "pow":
        left = f"\\left({left}\\right)" if lp < _ATOM else left
        return f"{left}^{{{right}}}", 4
    prec = _PREC[kind]
    left = f"\\left({left}\\right)" if lp < prec else left
    right = f"\\left({right}\\right)" if rp <= prec or rp == 3 else right
    if kind == "mul":
        separator = " \\cdot " if right[0] in "0123456789.-" else " "
        return f"{left}{separator}{right}", prec
    return f"{left} {_SYMBOLS[kind]} {right}", prec


def _program(root):
    """RPN (ops, args) of the tree below root, emitted without recursion."""
    ops, args = [], []
    stack = [(root, False)]
    while stack:
        node, ready = stack.pop()
        kind = node[0]
        if kind == "num":
            ops.append(OP_CONST)
            args.append(node[1])
        elif kind == "pi":
            ops.append(OP_CONST)
            args.append(math.pi)
        elif kind == "t":
            ops.append(OP_T)
            args.append(0.0)
        elif ready:
            ops.append(_BINARY.get(kind) or _UNARY[kind])
            args.append(0.0)
        else:
            stack.append((node, True))
            stack.extend((kid, False) for kid in reversed(_children(node)))
    return np.array(ops, dtype=np.int64), np.array(args, dtype=np.float64)


class Expr:
    """Immutable expression of t, made by parse() or derivative()."""

    __slots__ = ("_args", "_derivative", "_node", "_ops", "_order", "_origin", "text")

    def __init__(self, node, origin=None, order=0):
        ops, args = _program(node)
        text = _fold(node, _text_node)[0]
        object.__setattr__(self, "_node", node)
        object.__setattr__(self, "_ops", ops)
        object.__setattr__(self, "_args", args)
        object.__setattr__(self, "_derivative", None)
        object.__setattr__(self, "_origin", text if origin is None else origin)
        object.__setattr__(self, "_order", order)
        object.__setattr__(self, "text", text)

    def __setattr__(self, name, value):
        raise AttributeError("Expr is immutable")

    def __repr__(self):
        return f"Expr({self.text!r})"

    def __str__(self):
        return self.text

    def derivative(self):
        """Exact, simplified d/dt."""
        if self._derivative is None:
            node = _fold(self._node, _diff_node)
            size = _fold(node, _size)
            order = self._order + 1
            if size > MAX_PROGRAM:
                raise ExprError(
                    f"beta(t) = {_short(self._origin)} is too complex: "
                    f"its derivative of order {order} needs {size} "
                    f"operations (at most {MAX_PROGRAM}); simplify the expression"
                )
            object.__setattr__(self, "_derivative", Expr(node, self._origin, order))
        return self._derivative

    def program(self):
        """RPN program (ops int64[L], args float64[L]) for evaluate()."""
        return self._ops.copy(), self._args.copy()

    def latex(self):
        """LaTeX rendering for display."""
        return _fold(self._node, _latex_node)[0]

    def singularity(self, t0, t1):
        """The first t in [t0, t1] where the expression or one of its first two derivatives is not
        finite, or where a divisor in them vanishes (a pole the samples can step over: the sign of
        each divisor's factors at SINGULAR_SAMPLES + 1 points, the zero then found by bisection);
        None where there is none."""
        ts = np.linspace(t0, t1, SINGULAR_SAMPLES + 1)
        rows = (self, self.derivative(), self.derivative().derivative())
        first = math.inf
        carriers = {}
        for row in rows:
            bad = ~np.isfinite(row(ts))
            if bad.any():
                first = min(first, ts[np.argmax(bad)])
            for divisor in _divisors(row._node):
                for c in _sign_carriers(divisor):
                    carriers.setdefault(_fold(c, _text_node)[0], c)
        for c in carriers.values():
            f = Expr(c)
            sign = np.sign(f(ts))
            change = np.flatnonzero(sign[:-1] * sign[1:] <= 0)  # NaN compares false
            if len(change):
                i = change[0]
                first = min(first, _root(f, ts[i], ts[i + 1], sign[i]))
        return None if first == math.inf else float(first)

    def __call__(self, t):
        """Value at t, a number or an array of numbers."""
        if np.ndim(t) == 0:
            return evaluate(self._ops, self._args, float(t))
        ts = np.ascontiguousarray(t, dtype=np.float64)
        out = np.empty_like(ts)
        evaluate_many(self._ops, self._args, ts.reshape(-1), out.reshape(-1))
        return out


def programs(expr, orders=3):
    """Programs of expr and its next orders-1 derivatives: (ops int64[orders, L], args float64[orders, L])."""
    if orders < 1:
        raise ValueError(f"orders must be at least 1, got {orders}")
    rows = [expr]
    while len(rows) < orders:
        rows.append(rows[-1].derivative())
    length = max(row._ops.size for row in rows)
    ops = np.full((orders, length), OP_END, dtype=np.int64)
    args = np.zeros((orders, length), dtype=np.float64)
    for k, row in enumerate(rows):
        ops[k, : row._ops.size] = row._ops
        args[k, : row._args.size] = row._args
    return ops, args


def zero_programs(orders=3):
    """Programs of the constant 0 and its derivatives, shaped (orders, 1) like programs()."""
    return np.full((orders, 1), OP_CONST, dtype=np.int64), np.zeros((orders, 1), dtype=np.float64)


@numba.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _run(ops, args, t, stack):
    sp = 0
    for i in range(ops.shape[0]):
        op = ops[i]
        if op == OP_CONST:
            stack[sp] = args[i]
            sp += 1
        elif op == OP_T:
            stack[sp] = t
            sp += 1
        elif op == OP_END:
            break
        elif op >= OP_NEG:
            x = stack[sp - 1]
            if op == OP_NEG:
                x = -x
            elif op == OP_SIN:
                x = math.sin(x)
            elif op == OP_COS:
                x = math.cos(x)
            elif op == OP_TAN:
                x = math.tan(x)
            elif op == OP_EXP:
                x = math.exp(x)
            elif op == OP_LOG:
                x = np.log(x)
            elif op == OP_SQRT:
                x = np.sqrt(x)
            else:
                x = math.tanh(x)
            stack[sp - 1] = x
        else:
            sp -= 1
            a = stack[sp - 1]
            b = stack[sp]
            if op == OP_MUL:
                a = a * b
            elif op == OP_ADD:
                a = a + b
            elif op == OP_SUB:
                a = a - b
            elif op == OP_DIV:
                a = a / b
            else:
                a = a**b
            stack[sp - 1] = a
    return stack[0] if sp > 0 else 0.0


@numba.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def evaluate(ops, args, t):
    """Value of one program row at t; an empty program is 0."""
    return _run(ops, args, t, np.empty(ops.shape[0] + 1))


@numba.njit(cache=True, fastmath={"contract"}, error_model="numpy")
def evaluate_many(ops, args, ts, out):
    """out[i] = evaluate(ops, args, ts[i]); returns out."""
    stack = np.empty(ops.shape[0] + 1)
    for i in range(ts.shape[0]):
        out[i] = _run(ops, args, ts[i], stack)
    return out
