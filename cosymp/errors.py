"""Errors with messages a user can act on."""


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
