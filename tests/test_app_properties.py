"""app/properties.py: Bokeh's property system with its per-class constants memoized gives what
Bokeh's own code gives, for every model class the app can build."""
import contextlib
import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import panel as pn
import pytest
from bokeh.core.property.container import Dict
from bokeh.core.property.dataspec import DataSpec
from bokeh.core.property.descriptors import PropertyDescriptor
from bokeh.model import Model

from app import properties

ROOT = Path(__file__).resolve().parent.parent
properties.install()
ORIGINAL = properties.ORIGINAL
pn.extension()  # Panel's models registered, as in a served page


def model_classes():
    return sorted({c for c in Model.model_class_reverse_map.values() if not getattr(c, "__abstract__", False)},
                  key=lambda c: c.__qualified_model__)


def instances():
    """One instance of every model class that builds without arguments (most do; deprecated ones too)."""
    built = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for cls in model_classes():
            with contextlib.suppress(Exception):  # a class with required properties has no default instance
                built.append(cls())
    return built


INSTANCES = instances()


def descriptors(obj):
    """The property descriptors of obj's class (an alias of another property has a descriptor of its
    own kind, which app/properties.py leaves as it is)."""
    return [d for d in map(obj.lookup, obj.properties(_with_props=True)) if isinstance(d, PropertyDescriptor)]


def test_most_model_classes_are_covered():
    assert len(INSTANCES) > 0.8 * len(model_classes()) > 300


def test_overridden_defaults_and_unstable_defaults_are_bokehs_per_class():
    for obj in INSTANCES:
        cls = type(obj)
        assert cls._overridden_defaults() == ORIGINAL["overridden_defaults"](cls), cls
        for desc in descriptors(obj):
            for _ in range(2):  # computed, then memoized
                assert desc.has_unstable_default(obj) == ORIGINAL["has_unstable_default"](desc, obj), (cls, desc.name)


def test_defaults_are_bokehs_and_only_immutable_stable_ones_are_shared():
    shared = 0
    for obj in INSTANCES:
        for desc in descriptors(obj):
            name = desc.name
            theirs = ORIGINAL["instance_default"](desc, obj)
            first, again = desc.instance_default(obj), desc.instance_default(obj)
            if properties.immutable(theirs) and not desc.has_unstable_default(obj):
                assert (first == theirs or math.isnan(theirs)) and again is first, (obj, name)
                shared += 1
            else:
                assert type(first) is type(theirs) and type(again) is type(theirs), (obj, name)
                if isinstance(theirs, list | dict | set):
                    assert again is not first, (obj, name)  # a mutable default is never shared
    assert shared > 5000


def test_a_themed_model_gets_its_theme_value():
    from bokeh.models import Title
    title = Title()
    assert title.text_font_size == Title().text_font_size
    title.apply_theme({"text_font_size": "33px"})
    assert title.text_font_size == "33px" and Title().text_font_size != "33px"


def dict_properties():
    found = {}
    for cls in model_classes():
        for name in cls.properties(_with_props=True):
            prop = cls.lookup(name).property
            for p in (prop, *getattr(prop, "type_params", ())):
                if isinstance(p, Dict):
                    found.setdefault(str(p), p)
    return list(found.values())


def outcome(fn, *args):
    """What fn(*args) gives: its value, or the type and text of what it raised."""
    try:
        return ("ok", fn(*args))
    except Exception as err:  # noqa: BLE001 - compared, not handled
        return ("error", type(err).__name__, str(err))


@pytest.mark.parametrize("detail", [True, False])
def test_dict_validation_accepts_and_refuses_what_bokeh_does(detail, monkeypatch):
    props = dict_properties()
    assert len(props) > 10
    values = [{}, {"a": 1}, {"a": "b"}, {"a": [1, 2]}, {1: "x"}, {"a": None}, {"x": {"y": 1}}, [], "text", None, 3]
    cases = [(p, v) for p in props for v in values]
    ours = [outcome(p.validate, v, detail) for p, v in cases]
    monkeypatch.setattr(Dict, "validate", ORIGINAL["dict_validate"])
    assert ours == [outcome(p.validate, v, detail) for p, v in cases]
    assert {o[0] for o in ours} == {"ok", "error"}


def test_data_specs_serialize_as_bokeh_does(monkeypatch):
    values = ["x", "red", "#ff0000", 1, 1.5, 0, None, (1, 2, 3), [1, 2], {"field": "x"}, {"value": 2}, "circle", True]
    cases = [(obj, d.name, v) for obj in INSTANCES for d in descriptors(obj) if isinstance(d.property, DataSpec)
             for v in values]
    assert len(cases) > 1000
    ours = [outcome(obj.lookup(name).property.to_serializable, obj, name, v) for obj, name, v in cases]
    monkeypatch.setattr(DataSpec, "to_serializable", ORIGINAL["to_serializable"])
    assert ours == [outcome(obj.lookup(name).property.to_serializable, obj, name, v) for obj, name, v in cases]


BUILD = """
import json, sys
import panel as pn
if sys.argv[1] == "memoized":
    from app import properties
    properties.install()
from bokeh.document import Document
from app.page import Design
from app.study import Study
from app.features import FEATURES
pn.extension(design=Design)
study = Study()
doc = Document()
for f in FEATURES:
    view = f.view(study, f.state(study) if f.state else None)
    doc.add_root(view.__panel__().get_root(doc))
out = doc.to_json()
print(json.dumps({"content": out.content, "buffers": [[b.id, b.to_base64()] for b in out.buffers or []]},
                 sort_keys=True, default=lambda buffer: buffer.id))
"""


def test_every_tab_serializes_the_same_with_and_without_memoized_properties():
    """Every tab's layout, built in a fresh process each way: the same document, model for model
    (ids included: a fresh process numbers its models in order of creation)."""
    docs = [subprocess.run([sys.executable, "-c", BUILD, how], cwd=ROOT, capture_output=True, text=True, check=True,
                           timeout=300).stdout for how in ("bokeh", "memoized")]
    plain, memoized = (json.loads(d) for d in docs)
    assert len(plain["content"]["roots"]) == len(memoized["content"]["roots"]) > 5
    assert plain == memoized
