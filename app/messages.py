"""Bokeh's messages without a pass over every model of the document in Python for each one.

Each PATCH-DOC the server writes builds a Serializer whose references map every synced model of
the document to a new Ref (`{id(obj): obj.ref for obj in references}`), and each message from the
page builds a Deserializer mapping every model by its id (`{obj.id: obj ...}`). A page here holds
about 2,100 models (its tabs are built ahead), and a scene change writes three messages and reads
three or four: 15-30 ms of the server's time in a change that took 75-100 ms (timed in the served
app on a 2-core machine: Serializer 2.3-7 ms, Deserializer 1.3-7 ms, the synced set 0.5-0.8 ms).

Here the maps are built by C loops (`zip`, `map`), and a Ref is made for the models a message
names, when it names them (`Refs`); a message read looks the models it names up in the document's
own map of its models (`Known`). What a message holds is what Bokeh's own code writes and reads:
tests/test_app_messages.py compares both on a document of every tab.
"""
from operator import attrgetter

from bokeh.core.serialization import Deserializer, Serializer
from bokeh.document.models import DocumentModelManager

ORIGINAL = {}  # name -> Bokeh's own function, for the tests
MODEL_ID = attrgetter("_id")  # Model.id without the property's Python call


class Refs(dict):
    """Serializer._references for a set of models: id(model) -> the model's Ref, made the first time
    the serializer asks for it; the refs the serializer adds (new models) are kept as it adds them."""

    def __init__(self, models):
        super().__init__()
        self.models = dict(zip(map(id, models), models))

    def __contains__(self, key):
        return dict.__contains__(self, key) or key in self.models

    def get(self, key, default=None):
        ref = dict.get(self, key)
        if ref is None:
            model = self.models.get(key)
            if model is None:
                return default
            ref = self[key] = model.ref
        return ref


class Known(dict):
    """Deserializer._references over the document's own map of its models (ID -> model): a model a
    message names is looked up there when it names it; the models the message creates are kept
    here, the document's map untouched."""

    def __init__(self, models):
        super().__init__()
        self.models = models

    def __contains__(self, key):
        return dict.__contains__(self, key) or key in self.models

    def get(self, key, default=None):
        model = dict.get(self, key)
        return model if model is not None else self.models.get(key, default)


def document_map(references):
    """The map (ID -> model) of the document whose models `references` lists, all of them, as
    Document.apply_json_patch passes them (`list(doc.models)`); None for any other list."""
    if not references:
        return None
    document = getattr(references[0], "document", None)
    manager = getattr(document, "models", None)
    models = getattr(manager, "_models", None)
    if not isinstance(models, dict) or len(models) != len(references):
        return None
    return models


def install():
    """Faster reference maps in this process (once; main.py runs for each page)."""
    if ORIGINAL:
        return
    ORIGINAL.update(serializer_init=Serializer.__init__, deserializer_init=Deserializer.__init__,
                    synced_references=DocumentModelManager.synced_references)

    def serializer_init(self, *, references=frozenset(), deferred=True, check_circular=False):
        ORIGINAL["serializer_init"](self, deferred=deferred, check_circular=check_circular)
        self._references = Refs(references)

    def deserializer_init(self, references=None, *, setter=None):
        ORIGINAL["deserializer_init"](self, setter=setter)
        models = document_map(references)
        if models is not None:
            self._references = Known(models)
        else:
            references = references or ()
            self._references = dict(zip(map(MODEL_ID, references), references))

    def synced_references(self):
        return set(self._models.values()).difference(self._new_models)

    Serializer.__init__ = serializer_init
    Deserializer.__init__ = deserializer_init
    DocumentModelManager.synced_references = property(synced_references)
