"""Bokeh's map of a document's models kept up to date by what changed, not by a walk of the page.

Bokeh keeps each document's models (`DocumentModelManager`) as the set reachable from its roots, and
recomputes that set by walking every model of the page whenever a change sets a property holding
models, or a `freeze()` ends. A page here holds 2,100-2,700 models once its tabs are built, and each
walk took 60-100 ms on this project's 2-core machine: about a third of a tab's first build on the
server, and of each step building a tab ahead (py-spy), during which no page is answered.

Here a change that only adds references (a layout's new children: tabs joining the page, a figure's
new renderers) attaches what it brought: the models it names that the document does not hold, and
what they reach that it does not hold (a model the document holds already has everything it reaches
in it). Anything else is walked as Bokeh does: a change that drops a reference (the dropped model may
be unreachable now), a root added or removed, and any call of `recompute` itself. A freeze that ends
with nothing changed walks nothing. tests/test_app_graph.py compares the map with a full walk after
every step of a page's build, its tab visits and its scene changes.
"""
from bokeh.document.models import DocumentModelManager
from bokeh.model import Model
from bokeh.model.util import visit_immediate_value_references, visit_value_and_its_immediate_references

ORIGINAL = {}  # name -> Bokeh's own function, for the tests


def referenced(value):
    """The models a property value names itself (in lists, dicts and non-model objects), by identity."""
    found = {}
    visit_value_and_its_immediate_references(value, lambda model: found.setdefault(id(model), model))
    return found


class Graph:
    """What changed in one document's graph since its last walk: models that may have joined, or
    `full` when only a walk can tell."""

    __slots__ = ("change", "full", "joined", "roots")

    def __init__(self):
        self.change = None  # (old, new) of the property being set (Model.trigger, just before invalidate)
        self.full = True  # no walk yet
        self.joined = []
        self.roots = []  # the roots' ids at the last walk

    def note(self):
        """Take the change the invalidation is for."""
        change, self.change = self.change, None
        if change is None:
            self.full = True
            return
        old, new = referenced(change[0]), referenced(change[1])
        if old.keys() - new.keys():
            self.full = True
        else:
            self.joined.extend(new.values())


def graph(manager):
    found = manager.__dict__.get("_cosymp_graph")
    if found is None:
        found = manager._cosymp_graph = Graph()
    return found


def settle(manager):
    """Bring the manager's map up to date: a walk where one is needed, else the joined models attached."""
    state = graph(manager)
    document = manager._document()
    if document is None:
        return
    if state.full or [root.id for root in document.roots] != state.roots:
        manager.recompute()
        return
    if not state.joined:
        return
    models = dict(manager._models)  # a new map, as a walk makes: a reader holding the old one keeps it whole
    pending, state.joined = state.joined, []
    attached = []

    def join(model):
        if model.id not in models:
            pending.append(model)

    while pending:
        model = pending.pop()
        if model.id in models:
            continue
        models[model.id] = model
        attached.append(model)
        visit_immediate_value_references(model, join)
    try:
        for model in attached:
            model._attach_document(document)  # raises for a model of another document, as in a walk
    except Exception:
        state.full = True  # the next settle walks, and attaches what this one left
        raise
    for model in attached:
        if model.name is not None:
            manager._models_by_name.add_value(model.name, model)
        manager._new_models.add(model)
    manager._models = models


def install():
    """Incremental model maps in this process (once; main.py runs for each page)."""
    if ORIGINAL:
        return
    ORIGINAL.update(trigger=Model.trigger, invalidate=DocumentModelManager.invalidate,
                    recompute=DocumentModelManager.recompute, pop_freeze=DocumentModelManager._pop_freeze)

    def trigger(self, attr, old, new, hint=None, setter=None):
        document = self._document
        if hint is None and document is not None:
            state = graph(document.models)
            state.change = (old, new)
            try:
                ORIGINAL["trigger"](self, attr, old, new, hint=hint, setter=setter)
            finally:
                state.change = None
            return
        ORIGINAL["trigger"](self, attr, old, new, hint=hint, setter=setter)

    def invalidate(self):
        graph(self).note()
        if self._freeze_count == 0:
            settle(self)

    def recompute(self):
        state = graph(self)
        ORIGINAL["recompute"](self)
        document = self._document()
        state.full, state.joined = False, []
        state.roots = [root.id for root in document.roots] if document is not None else []

    def _pop_freeze(self):
        self._freeze_count -= 1
        if self._freeze_count == 0:
            settle(self)

    Model.trigger = trigger
    DocumentModelManager.invalidate = invalidate
    DocumentModelManager.recompute = recompute
    DocumentModelManager._pop_freeze = _pop_freeze
