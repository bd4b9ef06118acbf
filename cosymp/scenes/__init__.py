"""The scene registry: every module of this package that defines a SCENE is a scene, defined
once, there. Adding a scene is adding its module."""
import importlib
import pkgutil


def _discovered():
    modules = (importlib.import_module(f"{__name__}.{m.name}") for m in pkgutil.iter_modules(__path__))
    scenes = [m.SCENE for m in modules if hasattr(m, "SCENE")]
    return {s.name: s for s in sorted(scenes, key=lambda s: (s.rank, s.name))}


SCENES = _discovered()


def cases():
    """Every scene's declared cases, as (scene, case) in registry order."""
    return [(s, c) for s in SCENES.values() for c in s.cases]


def lead():
    """The (scene, case) marked as the lead: the app's first view."""
    return next((s, c) for s, c in cases() if c.lead)


def first(scene):
    """The case a scene declares as its first view (Case.first): what the app opens when the scene
    is picked from its menu."""
    return next(c for c in scene.cases if c.first)
