"""Warm-up for `panel serve app --setup app/warmup.py`: before the first page, load (or, on a
cold cache, compile) every compiled kernel the app can call, import the plotting stack and
compile datashader's aggregation.

The kernels are numba functions cached on disk (`__pycache__` beside cosymp's sources, or
NUMBA_CACHE_DIR). On a warm cache this takes about six seconds (four of them datashader's
aggregation, which has no disk cache); on a cold one (a fresh install, or after any change to
cosymp's sources, which invalidates the cache) it compiles everything once, one to three
minutes. Run `python app/warmup.py` to fill the cache ahead of time.
"""
import importlib
import time

RASTER_COLUMNS = ("x", "y")  # the column names of every rasterized portrait (views.raster_dims)


def warm():
    """Run every method on every scene it applies to (a few steps, with the tangent maps, the
    carried loop and the exact flow that compare() uses; one work-precision point, scipy's
    solvers and one long-horizon point, one stability-map point), the gauge study, import the
    plotting modules the pages use and compile datashader's aggregation. Returns the wall time in
    seconds."""
    from cosymp import sweep
    from cosymp import workprecision as wp
    from cosymp.integrate import Setup
    from cosymp.methods import METHODS
    from cosymp.scenes import SCENES
    from cosymp.study import compare, gauge_study

    start = time.perf_counter()
    for scene in SCENES.values():
        methods = [m.name for m in METHODS.values() if m.refusal(scene) is None]
        for name in methods:
            compare(Setup.make(scene, name), scene.h, 10 * scene.h, cloud_points=8)
        measured = [m for m in methods if m != "exact"]
        wp.measure(scene.name, measured, T=4 * scene.h, hs=[scene.h], peers=True, rtols=(1e-3,), budget=0.0)
        wp.drift(scene.name, measured, h=scene.h, horizons=[2 * scene.h])
        sweep.figures(Setup.make(scene, measured[0]), scene.h, 4 * scene.h, sweep.MEASURES)
    gauge_study("midpoint", {}, SCENES["charged"].h, 10 * SCENES["charged"].h)
    for module in ("holoviews.plotting.bokeh", "holoviews.operation.downsample", "tsdownsample"):
        importlib.import_module(module)
    rasterize_once()
    return time.perf_counter() - start


def rasterize_once():
    """Rasterize a small path as dense portraits are (columns RASTER_COLUMNS): datashader compiles
    its aggregation for each pair of column names on first use, without a disk cache (about 4 s
    and 150 MB, on the event loop of whichever page first shows more than DENSE_RECORDS records)."""
    import holoviews as hv
    import numpy as np
    from holoviews.operation.datashader import datashade

    x = np.linspace(0.0, 1.0, 16)
    datashade(hv.Path(dict.fromkeys(RASTER_COLUMNS, x), list(RASTER_COLUMNS)), cmap=["#000000"], dynamic=False,
              width=8, height=8)


if __name__ in ("__main__", "panel_setup_module"):
    print(f"cosymp app warm-up: kernels and plotting stack ready in {warm():.1f} s", flush=True)
