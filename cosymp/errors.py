"""Errors with messages a user can act on."""
import math
import numbers

QUOTE_LIMIT = 60


def one_line(text, limit, quote=""):
    """text on one line (control characters escaped), between `quote`s, cut to `limit` characters
    with its length said."""
    text = str(text)
    shown = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text[:limit])
    return quote + shown + quote + (f"... ({len(text)} characters)" if len(text) > limit else "")


def quoted(value, limit=QUOTE_LIMIT):
    """User text as a message shows it: quoted, on one line, cut to `limit` characters."""
    return one_line(value, limit, quote="'")


def as_number(value, label):
    """A finite float from a number (Python's or NumPy's, not bool), or InputError naming label."""
    if type(value) is float and math.isfinite(value):  # the common case, without the ABC checks
        return value
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{label} = {quoted(value)} is not a number: pass a finite {label}")
    try:
        x = float(value)
    except OverflowError:
        raise InputError(f"{label} is too large for a double: pass a finite {label}") from None
    if not math.isfinite(x):
        raise InputError(f"{label} = {x} is not a finite number: pass a finite {label}")
    return x


class CosympError(Exception):
    """Base class: the message is one line saying what went wrong and what to change."""


class InputError(CosympError, ValueError):
    """Bad input: a parameter, step size, horizon or name that cannot be used."""


class RunError(CosympError, RuntimeError):
    """A run that could not go on: overflow or a Newton iteration that did not converge."""

    def __init__(self, message, time, step, partial=None):
        super().__init__(message)
        self.time = time
        self.step = step
        self.partial = partial
