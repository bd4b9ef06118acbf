"""app/messages.py: Bokeh's messages written and read with the faster reference maps hold what
Bokeh's own code writes and reads, on a document of every tab."""
import json

import numpy as np
import panel as pn
from bokeh.core.serialization import Deserializer, Serializer
from bokeh.document import Document
from bokeh.document.models import DocumentModelManager
from bokeh.model import Model
from bokeh.models import ColumnDataSource, Div, Title
from bokeh.protocol.messages.patch_doc import patch_doc

from app import messages
from app.features import FEATURES
from app.page import Design
from app.study import Study

messages.install()
pn.extension(design=Design)


def plain(x):
    """A decoded value with its models named (type and id) and its arrays as lists."""
    if isinstance(x, Model):
        return ("model", type(x).__name__, x.id)
    if isinstance(x, dict):
        return {k: plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return ("array", x.dtype.str, x.tolist())
    return x


def every_tab():
    study = Study()
    doc = Document()
    for f in FEATURES:
        view = f.view(study, f.state(study) if f.state else None)
        doc.add_root(view.__panel__().get_root(doc))
    doc.models.flush_synced()  # as after the page has pulled the document
    return doc


def with_original(monkeypatch):
    monkeypatch.setattr(Serializer, "__init__", messages.ORIGINAL["serializer_init"])
    monkeypatch.setattr(Deserializer, "__init__", messages.ORIGINAL["deserializer_init"])
    monkeypatch.setattr(DocumentModelManager, "synced_references", messages.ORIGINAL["synced_references"])


def test_a_patch_is_written_and_read_as_bokeh_does(monkeypatch):
    doc = every_tab()
    assert len(doc.models) > 1000
    events = []
    doc.on_change(events.append)
    source = next(m for m in doc.models if isinstance(m, ColumnDataSource) and m.data)
    source.data = {k: np.arange(5.0) + i for i, k in enumerate(source.data)}  # buffers
    column = next(m for m in doc.models if type(m).__name__ == "Column" and m.children)
    new = Div(text="new")
    column.children = [*column.children, new]  # a new model: written out in full, referring to old ones
    next(m for m in doc.models if isinstance(m, Title)).text = "another title"
    assert len(events) == 3
    new_models = set(doc.models._new_models)
    assert new in new_models

    def written():
        """The message's content (its buffers named by their order: each message makes new ids),
        its buffers, what it decodes to, and the models still new after it."""
        doc.models._new_models = set(new_models)
        assert doc.models.synced_references == set(doc.models) - new_models
        msg = patch_doc.create(events)
        order = [b.id for b in msg.buffers]
        text = json.dumps(msg.content, sort_keys=True, default=lambda b: f"buffer {order.index(b.id)}")
        decoded = plain(Deserializer(list(doc.models)).decode(msg.content, msg.buffers))
        return text, [b.to_bytes() for b in msg.buffers], decoded, set(doc.models._new_models)

    ours = written()
    with monkeypatch.context() as m:
        with_original(m)
        bokeh = written()
    assert ours == bokeh
    assert len(ours[1]) == len(source.data) and not ours[3], "buffers sent; the new model synced once written"
    assert ("model", "Div", new.id) in ours[2]["events"][1]["new"], "the new model, decoded"


def test_a_message_read_looks_up_the_document_s_own_map_and_leaves_it_as_it_was():
    """Deserializer's references for a document's models are that document's own map (no dict of
    every model built per message); a model the message creates is the deserializer's, not added to
    the document's map; any other list is mapped as Bokeh does."""
    doc = every_tab()
    known = doc.models._models
    size = len(known)
    reader = Deserializer(list(doc.models))
    assert isinstance(reader._references, messages.Known) and reader._references.models is known
    some = next(iter(doc.models))
    assert reader.has_ref(some) and reader._references.get(some.id) is some
    fresh = Div(text="fresh")
    content = Serializer(references=set(doc.models)).encode(fresh)
    decoded = reader.decode(content)
    assert isinstance(decoded, Div) and decoded.text == "fresh" and decoded.id == fresh.id
    assert reader._references.get(fresh.id) is decoded and fresh.id not in known and len(known) == size
    assert type(Deserializer([some])._references) is dict
