"""Progress on stderr: a one-line bar drawn only on a terminal (`Bar`), or lines for a log (`Lines`)."""
import contextlib
import shutil
import sys
import time


class Bar:
    """Callable as progress(done, total, label); `close()` ends the line."""

    def __init__(self, stream=None, width=28, force=False):
        self.stream = stream or sys.stderr
        self.width = width
        self.on = force or self.stream.isatty()
        self.drawn = False

    def __call__(self, done, total, label=""):
        if not self.on:
            return
        frac = min(1.0, done / total) if total else 1.0
        filled = round(frac * self.width)
        line = f"[{'#' * filled}{'.' * (self.width - filled)}] {done}/{total} {label}"
        cols = shutil.get_terminal_size((100, 20)).columns - 1
        self.stream.write("\r" + line[:cols].ljust(cols))
        self.stream.flush()
        self.drawn = True

    def close(self):
        if self.drawn:
            self.stream.write("\n")
            self.stream.flush()
            self.drawn = False


class Lines:
    """Callable as progress(done, total, label), for a stream that is not a terminal (a log, a CI
    job, a pipe), where a bar is not drawn: a line when a stage begins (`done` and the label both
    change) or ends the work (`done` reaches `total`), and otherwise the latest count and label at
    most every `every` seconds, each with the seconds since the start. A count under one label
    (a sweep's points) is thus a line every `every` seconds, not one per point."""

    def __init__(self, stream=None, every=10.0, prefix="cosymp: "):
        self.stream = stream or sys.stderr
        self.every = every
        self.prefix = prefix
        self.started = self.last = time.perf_counter()
        self.done = self.label = None

    def __call__(self, done, total, label=""):
        now = time.perf_counter()
        stage = done != self.done and (label != self.label or done == total)
        if not stage and now - self.last < self.every:
            return
        self.done, self.label, self.last = done, label, now
        self.stream.write(f"{self.prefix}{now - self.started:6.1f} s  [{done}/{total} done] {label}\n")
        self.stream.flush()

    def close(self):
        """Nothing to end: every line is complete."""


def for_stream(stream):
    """A Bar on a terminal, else Lines."""
    return Bar(stream) if stream.isatty() else Lines(stream)


@contextlib.contextmanager
def shown(stream):
    """for_stream(stream) for a with block, closed at its end (a bar's line ended before the results
    are printed): how the long commands report progress."""
    progress = for_stream(stream)
    try:
        yield progress
    finally:
        progress.close()
