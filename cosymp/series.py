"""Long series reduced for display, so that no extreme is lost (the app's plots and the reports)."""
import math

import numpy as np

FLOOR = 1e-17  # exact zeros of a deviation are drawn here on log axes


def zero_floor(ys):
    """Where exact zeros are drawn on a log axis among these series: FLOOR, or a decade below their
    smallest nonzero value when that is smaller (charged's paper volume estimator is 8e-45 for RK4
    and exactly 0 for midpoint: at FLOOR the zero was drawn above the data, and the data not at all)."""
    small = []
    for y in ys:
        a = np.abs(np.asarray(y, float))
        a = a[np.isfinite(a) & (a > 0)]
        if a.size:
            small.append(np.min(a))
    return min([FLOOR] + [v / 10 for v in small])


def envelope(x, y, max_points):
    """(x, y) reduced to at most max_points: per bin of consecutive points the minimum and the
    maximum of y, in the order they occur, so extremes and oscillation bands stay visible; a bin
    of NaN keeps one NaN (a gap). Short series pass as they are."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    n = len(y)
    if n <= max_points:
        return x, y
    bins = max(1, max_points // 2)
    width = math.ceil(n / bins)
    bins = math.ceil(n / width)
    grid = np.full(bins * width, np.nan)
    grid[:n] = y
    grid = grid.reshape(bins, width)
    missing = np.isnan(grid)
    lo = np.argmin(np.where(missing, np.inf, grid), axis=1)
    hi = np.argmax(np.where(missing, -np.inf, grid), axis=1)
    start = np.arange(bins) * width
    keep = np.unique(np.stack([np.minimum(lo, hi), np.maximum(lo, hi)], axis=1) + start[:, None])
    keep = keep[keep < n]
    return x[keep], y[keep]


def thin(x, y, max_points):
    """A parametric curve (x, y) reduced to at most max_points evenly spaced points, in order."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if len(x) <= max_points:
        return x, y
    keep = np.unique(np.linspace(0, len(x) - 1, max_points).round().astype(int))
    return x[keep], y[keep]
