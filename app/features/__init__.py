"""The app's tabs: one module per feature, each holding its state and its view, and one registry.

A feature is a `Feature`: its name (the view's key in the URL), its tab's label, a factory of its
state for a page (a `jobs.Job`, or None when it shows the sidebar's comparison) and of its view,
and the state's parameters the URL carries. main.py walks FEATURES: adding a tab is one module
and one line here.
"""
from . import cloud, gauges, longrun, orbits, play, stabilitymap, structure, theta, workprecision
from .base import Feature, FeatureView

FEATURES = tuple(m.FEATURE for m in (orbits, structure, cloud, gauges, theta, play, longrun, workprecision,
                                     stabilitymap))

__all__ = ["FEATURES", "Feature", "FeatureView"]
