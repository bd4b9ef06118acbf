"""The scene registry: every scene is defined once, in its own module."""
from . import charged, damped, decaying, kapitza, modulated

SCENES = {s.name: s for s in (decaying.SCENE, damped.SCENE, modulated.SCENE, charged.SCENE,
                              kapitza.SCENE)}
KERNELS = {s.Params: s.kernel for s in SCENES.values()}
