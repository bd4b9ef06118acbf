"""A one-line progress bar on the terminal (stderr), drawn only when it is a terminal."""
import shutil
import sys


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
