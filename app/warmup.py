"""The app's kernels, compiled before they are needed.

`python app/warmup.py` compiles every kernel that is not in numba's disk cache yet, in one
process per core, with progress (the same as `cosymp compile`), and returns at once on a warm
cache.

`panel serve app --setup app/warmup.py` runs `prepare()` before the server starts. On a warm
cache it loads every kernel (a few seconds). On a cold
cache (a fresh install, or after a change to the sources the kernels are built from) it compiles
the first page's kernels in one process per core, serves, and compiles the rest in lowered-
priority processes meanwhile; a run whose kernels are still being compiled waits for them
(cosymp.warm.ensure), and later kernels load from the cache on first use. The server itself
never compiles a kernel, so it stays at its warm size.
"""
import time


def first_view():
    """What the app shows first (study.Study's defaults; presets.PRESETS[0]): the case a scene
    declares as the lead (on the modulated oscillator, RK4's |H + p_t| starts below the symplectic
    method's bounded band, drifts, and passes it). Its kernels are compiled first."""
    from cosymp.scenes import lead

    scene, case = lead()
    return {"scene": scene.name, "method": case.method, "other": case.other, "h": case.h, "T": case.T,
            "values": dict(case.values)}


def first_keys():
    """The compile units the first page runs (both methods and the scene's exact flow, for its
    error), in the order that makes them ready soonest on two cores: the first method's beside
    the exact flow's and then the other method's (a worker's first unit also pays its start-up)."""
    from cosymp import warm
    from cosymp.integrate import Setup
    from cosymp.scenes import SCENES

    first = first_view()
    scene = SCENES[first["scene"]]
    methods = [first["method"]] + (["exact"] if scene.has_flow else []) + [first["other"]]
    return list(dict.fromkeys(warm.key_of(Setup.make(scene, m)) for m in methods))


def prepare(report=print, preload=True):
    """Make the kernels ready (see the module's doc); with preload, load them into this process
    (every kernel on a warm cache, the first page's on a cold one).
    Returns the seconds it took."""
    from cosymp import warm

    start = time.perf_counter()
    first = first_keys()
    compiler = warm.start(first, report=lambda line: report(f"cosymp compile {line}"))
    if compiler is None:
        if preload:
            for unit in warm.units():
                unit.run()
        return time.perf_counter() - start
    compiler.wait(first)
    if preload:
        for unit in warm.units():
            if unit.key in first:
                unit.run()
    return time.perf_counter() - start


if __name__ == "__main__":
    from cosymp.cli import main

    raise SystemExit(main(["compile"]))
if __name__ == "panel_setup_module":
    import panel as pn

    # A page's HTML comes from the first session's, at once, and its own session is built meanwhile,
    # while the browser loads the scripts: the page's request took 0.37-0.8 s, the time to build a
    # session. Every session's template is the same; what a link asks for is applied when its session
    # is built. (Set here, the server's setup: `panel serve` cannot import the app package yet.)
    pn.config.reuse_sessions = "warm"
    print(f"cosymp app warm-up: ready in {prepare():.1f} s", flush=True)
    import gc

    # What the server holds now (modules, compiled kernels) lives as long as it does: full garbage
    # collections no longer go through it (13 ms of each).
    gc.freeze()
