"""app/graph.py: a document's map of its models, kept up to date by what changed, is the map a walk
of the page gives, through a page's build, its tabs built ahead and visited, and its scene changes;
and it walks only where a change may have dropped a model."""
import panel as pn
import pytest
from bokeh.document import Document
from bokeh.models import ColumnDataSource, Div, Range1d
from panel.io.state import set_curdoc

from app import graph, main, plotting
from app.features import FEATURES
from app.plotting import push


def walked(doc):
    """The models reachable from the document's roots: Bokeh's own definition of its map."""
    found = set()
    for root in doc.roots:
        found |= root.references()
    return found


def assert_map_is_the_walk(doc, label):
    reachable = walked(doc)
    held = set(doc.models)
    assert held == reachable, f"{label}: {len(held - reachable)} held and unreachable, {len(reachable - held)} missed"
    assert all(doc.models.get_by_id(m.id) is m and m.document is doc for m in reachable), label
    names = {m.name for m in reachable if m.name is not None}
    assert all(set(doc.models.get_all_by_name(n)) == {m for m in reachable if m.name == n} for n in names), label


@pytest.fixture
def walks(monkeypatch):
    """Every full walk of a document's models (Bokeh's recompute) made while the test runs."""
    made = []
    recompute = graph.ORIGINAL["recompute"]
    monkeypatch.setitem(graph.ORIGINAL, "recompute", lambda manager: (made.append(manager), recompute(manager)))
    return made


def test_a_page_s_map_follows_its_build_its_tabs_and_scene_changes_and_tabs_join_without_a_walk(walks):
    app = main.App()
    doc = Document()
    with set_curdoc(doc):
        with doc.models.freeze():
            app.template().server_doc(doc)
        assert_map_is_the_walk(doc, "the page")
        walks.clear()
        steps = 0
        for step in app._ahead_work():
            held = set(doc.models)
            doc.models.flush_synced()  # as a message sent leaves it
            push(step)
            steps += 1
            assert_map_is_the_walk(doc, f"step {steps} built ahead")
            assert doc.models._new_models == set(doc.models) - held, "what the next message sends whole"
        assert steps > 10 and walks == [], "tabs built ahead join by adding references: no walk"
        for i, f in enumerate(FEATURES):
            push(lambda name=f.name: app._show(name))
            assert len(app.tabs[i]) == 1
            assert_map_is_the_walk(doc, f"tab {f.name} shown")
        assert walks == [], "a tab's first visit adds references only"
        assert len(doc.models) > 2000
        for scene in ("charged", "kapitza", "decaying", "modulated", "damped", "charged"):
            app.study.param.update(scene=scene)
            assert app.study.results is not None and app.study.message is None, scene
            assert_map_is_the_walk(doc, f"scene {scene}")
        for method in ("gauss4", "symplectic-euler"):
            app.study.param.update(method=method)
            assert_map_is_the_walk(doc, f"method {method}")
    app._stop(None)


def test_a_dropped_reference_is_walked_and_detached_and_a_quiet_freeze_walks_nothing(walks):
    doc = Document()
    fig = plotting.figure("t")
    source = ColumnDataSource({"x": [0.0], "y": [1.0]})
    fig.line("x", "y", source=source)
    doc.add_root(fig)
    assert_map_is_the_walk(doc, "root")
    walks.clear()
    with doc.models.freeze():
        source.data = {"x": [1.0, 2.0], "y": [3.0, 4.0]}
    assert walks == [], "a data update changes no reference"
    old, new = fig.x_range, Range1d(0, 1)
    with doc.models.freeze():
        fig.x_range = new
        assert doc.models.get_by_id(new.id) is None, "taken in when the freeze ends"
    assert len(walks) == 1, "a replaced reference may have dropped its model: one walk"
    assert old.document is None and doc.models.seen(old.id) and new.document is doc
    assert_map_is_the_walk(doc, "replaced range")
    walks.clear()
    div = Div(text="later", name="later")
    second = Div(text="second root")
    with doc.models.freeze():
        doc.add_root(second)
    assert len(walks) == 1 and second.document is doc, "a root added: one walk"
    walks.clear()
    fig.renderers = [*fig.renderers]  # same models: nothing joins, nothing drops
    fig.above = [*fig.above, div]
    assert walks == [] and div.document is doc and div in doc.models._new_models, "sent whole in the next message"
    assert doc.models.get_one_by_name("later") is div
    assert_map_is_the_walk(doc, "added outside a freeze")


def test_a_layout_s_new_children_join_the_map_at_the_end_of_one_push(walks):
    doc = Document()
    column = pn.Column(pn.pane.Markdown("a"))
    doc.add_root(column.get_root(doc))
    walks.clear()
    figure = plotting.figure("new")
    with set_curdoc(doc):
        push(lambda: column.append(pn.pane.Bokeh(figure)))  # Panel's freeze_doc ends inside
    assert walks == [] and doc.models._freeze_count == 0
    assert figure.document is doc and figure.x_range.document is doc
    assert_map_is_the_walk(doc, "appended")


def test_a_push_that_raises_leaves_the_document_unfrozen_and_its_additions_attached(walks):
    """Bokeh's freeze() stays frozen when its body raises; push's must not, or nothing added to the
    page afterwards would ever reach it."""
    doc = Document()
    column = pn.Column(pn.pane.Markdown("a"))
    doc.add_root(column.get_root(doc))
    first, later = plotting.figure("first"), plotting.figure("later")

    def fails():
        column.append(pn.pane.Bokeh(first))
        raise ValueError("a bad update")

    with set_curdoc(doc):
        with pytest.raises(ValueError):
            push(fails)
        assert doc.models._freeze_count == 0 and first.document is doc
        column.append(pn.pane.Bokeh(later))
    assert later.document is doc
    assert_map_is_the_walk(doc, "after a failed push")


def test_a_model_of_another_document_fails_as_in_bokeh_and_the_next_change_walks(walks):
    doc, other = Document(), Document()
    fig = plotting.figure("t")
    doc.add_root(fig)
    foreign = Div(text="elsewhere")
    other.add_root(foreign)
    walks.clear()
    mine = Div(text="mine")
    with pytest.raises(RuntimeError):
        fig.above = [*fig.above, mine, foreign]
    other.remove_root(foreign)
    fig.above = [*fig.above, Div(text="more")]  # the next change walks: the failed one left models to attach
    assert walks.count(doc.models) == 1 and mine.document is doc and foreign.document is doc
    assert_map_is_the_walk(doc, "after the foreign model left its document")
