"""The served page (app/main.py) composed in-process, without a server or a browser."""
import asyncio
import builtins
import dataclasses
import datetime
import importlib
import inspect
import math
import pathlib
import threading
import types

import panel as pn

from app import jobs, main, memory, page
from app.features import FEATURES, base, theta, workprecision
from app.jobs import Job
from cosymp.scenes import SCENES


def test_the_page_has_every_view_and_follows_the_study():
    app = main.App()
    page = app.template()
    assert isinstance(page, pn.template.BootstrapTemplate)
    assert len(app.tabs) == len(FEATURES)
    names = [f.name for f in FEATURES]
    assert app.tabs.active == names.index(app.study.view)
    app.study.view = "structure"
    assert app.tabs.active == names.index("structure")
    app.tabs.active = names.index("long")
    assert app.study.view == "long"
    assert app.study.results is not None and all(e.comparison is not None for e in app.study.results.entries)


def test_the_spinner_spins_while_any_computation_of_the_page_runs():
    """Not only the comparison: a tab's lesson, study, run or map computing shows it too (a tab
    showing what it showed before a change said nothing)."""
    app = main.App()
    page = app.template()
    [spinner] = [o for obj in page.main for o in obj.select(pn.indicators.LoadingSpinner)]
    assert spinner.styles == {"opacity": "0"}
    kinds = {type(j).__name__ for j in app.jobs}
    assert {"Study", "ThetaLesson", "LongRun", "StabilityMap", "WorkPrecision", "LongHorizons"} <= kinds, kinds
    for job in app.jobs:
        job.running = True
        assert spinner.styles == {"opacity": "1"}, job
        job.running = False
        assert spinner.styles == {"opacity": "0"}, job
    app.study.running = True
    assert spinner.styles == {"opacity": "1"}
    app._stop(None)


def test_a_tab_is_built_when_first_shown_and_closing_the_page_releases_every_state():
    app = main.App()
    names = [f.name for f in FEATURES]
    shown = app.tabs[names.index("compare")]
    assert len(shown) == 1 and all(not len(app.tabs[i]) for i, n in enumerate(names) if n != "compare")
    app.study.view = "theta"
    assert len(app.tabs[names.index("theta")]) == 1 and app.states["theta"].results is not None
    # As Bokeh destroys a session whose page never connected: the page script's namespace emptied first.
    stop = types.FunctionType(main.App._stop.__code__, {"__builtins__": builtins}, "_stop")
    stop(app, None)
    assert app.study._closed and all(s is None or getattr(s, "_closed", True) for s in app.states.values())


def test_the_bokeh_reads_shim_still_matches_bokehjs_and_no_css_sets_bk_variables():
    """app/static/bokeh_reads.js replaces two BokehJS reads of computed style (every visual
    property through --bk-* CSS variables; a plot's font size). It is only right while cosymp sets
    no --bk-* variable, and only useful while BokehJS still reads them that way: when a Bokeh
    release changes either, this says so."""
    import re
    from pathlib import Path

    import bokeh

    js = (Path(bokeh.__file__).parent / "server" / "static" / "js" / "bokeh.js").read_text()
    assert re.search(r"_get_css_value\(name\) \{\s*const style = getComputedStyle\(this\.obj\.el\);", js), \
        "BokehJS no longer reads visuals through getComputedStyle: app/static/bokeh_reads.js may go"
    assert re.search(r"get base_font_size\(\) \{\s*const font_size = getComputedStyle\(this\.el\)\.fontSize;", js), \
        "BokehJS no longer reads a plot's font size through getComputedStyle: revisit app/static/bokeh_reads.js"
    assert re.search(r"_after_render\(\) \{\s*this\.update_style\(\);\s*this\.update_bbox\(\);\s*\}", js), \
        "BokehJS's elements no longer read their size as they render: revisit app/static/bokeh_reads.js"
    assert re.search(r"build\(target\) \{\s*\(0, assert_1\.assert\)\(this\.is_root\);\s*this\.render_to\(target\);"
                     r"\s*this\.r_after_render\(\);", js), "BokehJS builds a root otherwise: revisit app/static/bokeh_reads.js"
    root = Path(main.__file__).resolve().parent.parent
    sources = [*root.glob("assets/*.css"), *root.glob("app/**/*.py"), *root.glob("app/**/*.js")]
    assert sources and not [p for p in sources if re.search(r"--bk-[a-z]", p.read_text())], \
        "a --bk-* CSS variable would be ignored by the figures (app/static/bokeh_reads.js)"
    assert all((root / path).is_file() for path in page.SCRIPTS.values())


def test_the_quiet_shim_still_matches_bokehjs():
    """app/static/bokeh_quiet.js keeps figures without data from warning: it turns the range
    manager's warning off after PlotView.initialize made it (as BokehJS's InternalPlotView does), and
    gives DataRange1d._compute_range of a log axis with no finite data BokehJS's own 0.1 ... 10. When a
    Bokeh release changes either, this says so. (tests/served.py fails an e2e test on any BokehJS
    warning.)"""
    import re
    from pathlib import Path

    import bokeh

    js = (Path(bokeh.__file__).parent / "server" / "static" / "js" / "bokeh.js").read_text()
    assert re.search(r"initialize\(\) \{\s*super\.initialize\(\);\s*this\._range_manager\.warn_initial_ranges = false;",
                     js), "BokehJS's internal plots no longer turn the warning off this way: revisit bokeh_quiet.js"
    assert "this._range_manager = new range_manager_1.RangeManager(this);" in js
    assert re.search(r"if \(this\.warn_initial_ranges\) \{\s*logging_1\.logger\.warn\(\"could not set initial ranges\"\);",
                     js)
    assert re.search(r"_compute_range\(min, max\) \{(?:(?!\n        \}).)*if \(this\.scale_hint == \"log\"\) \{\s*"
                     r"if \(isNaN\(min\) \|\| !isFinite\(min\) \|\| min <= 0\) \{\s*"
                     r"if \(isNaN\(max\) \|\| !isFinite\(max\) \|\| max <= 0\) \{\s*min = 0\.1;", js, re.DOTALL), \
        "DataRange1d takes another log range without data: revisit app/static/bokeh_quiet.js"
    assert re.search(r"max <= 0\) \{\s*if \(isNaN\(min\) \|\| !isFinite\(min\) \|\| min <= 0\) \{\s*max = 10;", js)
    assert '"models/plots/plot_canvas":' in js and '"models/ranges/data_range1d":' in js


def test_the_equations_are_typeset_on_the_server_with_katexs_stylesheet_and_every_font_it_names():
    """plotting.typeset runs the KaTeX release whose stylesheet and fonts app/static/katex holds
    (Panel's bundled sheet names fonts it does not ship), and every equation gets that sheet, each
    font's URL pointing at a file the app serves. The page loads no KaTeX script."""
    import re

    from panel.io.resources import Resources

    from app import plotting

    version = re.compile(r"katex-version:after\{content:\"([0-9.]+)\"\}|version:\"([0-9.]+)\"")
    css_version = version.search((plotting.KATEX / "katex.min.css").read_text()).group(1)
    assert css_version and css_version == version.search((plotting.KATEX / "katex.min.js").read_text()).group(2)
    urls = re.findall(r"url\(([^)]+)\)", plotting.katex_css())
    assert len(urls) > 10 and urls == re.findall(r"url\(([^)]+)\)", plotting.katex_fonts_css())
    assert all(u.startswith(plotting.KATEX_URL) and u.endswith(".woff2")
               and (plotting.KATEX / u.removeprefix(plotting.KATEX_URL)).is_file() for u in urls)
    eq = plotting.equation(r"\dot q = p")
    assert plotting.katex_css() in eq.stylesheets and eq.disable_math
    assert 'class="katex-html"' in eq.object and '<annotation encoding="application/x-tex">\\dot q = p</annotation>' in eq.object
    assert plotting.equation("").object == ""
    # The fonts are declared once, in the page's head (a shadow root's @font-face is ignored; as
    # raw_css they were copied into every component: half of the first page's document).
    assert plotting.katex_fonts_css() in pn.config.global_css and plotting.katex_fonts_css() not in pn.config.raw_css
    assert not [f for f in Resources(mode="server").js_files if "katex" in f.lower()]


def test_text_katex_cannot_typeset_shows_as_its_source_and_nothing_runs_or_links():
    """An equation's TeX can hold what a user typed (beta(t)): an unparseable one shows as its
    source in red with KaTeX's message, a macro that expands forever stops at KaTeX's limit, and
    no command makes a link or runs script (KaTeX's trust is off)."""
    from app import plotting

    broken = plotting.typeset(r"\frac{1}{")
    assert broken.startswith('<span class="katex-error"') and "ParseError" in broken and "color:#cc0000" in broken
    assert "Too many expansions" in plotting.typeset(r"\def\a{\a}\a")
    for tex in (r"\href{javascript:alert(1)}{x}", r"\url{https://example.com}", r"\htmlData{onclick=x}{y}",
                "</span><script>alert(1)</script>"):
        out = plotting.typeset(tex)
        assert "<a " not in out and "<script" not in out and "onclick" not in out.replace("onclick=x", ""), tex


def test_components_get_bootstraps_reboot_and_the_page_the_whole_of_bootstrap():
    """app/static/bootstrap_reboot.css is the Reboot section of the Bootstrap that Panel bundles,
    verbatim; each component gets it in place of the whole sheet, which the page keeps."""
    from pathlib import Path

    import panel
    from bokeh.document import Document

    whole = (Path(panel.__file__).parent / "dist" / "bundled" / "bootstrap5" / "css" / "bootstrap.min.css").read_text()
    reboot = (Path(main.__file__).resolve().parent.parent / page.REBOOT).read_text()
    section = reboot[reboot.index("*/") + 2:].strip()
    assert section.startswith("*,::after,::before{box-sizing:border-box}") and section in whole, \
        "Panel bundles another Bootstrap: extract its Reboot section again"
    assert whole[whole.index(section) + len(section):].startswith(".lead{")
    template = main.App().template()
    doc = template.server_doc(Document())
    urls = [s.url for m in doc.models if hasattr(m, "stylesheets") for s in m.stylesheets if hasattr(s, "url")]
    assert page.REBOOT in urls and not [u for u in urls if u.endswith("bootstrap.min.css")]
    assert any("bootstrap.min.css" in str(u) for u in template.resolve_resources()["css"].values())


def test_panel_handles_a_change_at_once_and_sends_what_it_causes_in_one_message():
    """app/page.adjust_panel: Panel's 50 ms wait before handling a change from the page is gone, and
    its handling runs under one hold (one message). Applied once per server, however many pages run
    main.py; and only useful while Panel still waits `_debounce` and handles a change in
    `_change_event`: when a Panel release changes either, this says so."""
    import inspect

    from panel.reactive import Syncable

    page.adjust_panel()
    page.adjust_panel()
    assert Syncable._debounce == 0
    assert Syncable._change_event.cosymp and not getattr(Syncable._change_event.__wrapped__, "cosymp", False)
    assert "self._debounce" in inspect.getsource(Syncable._server_change), "Panel no longer debounces this way"
    assert "self._change_event(doc)" in inspect.getsource(Syncable._change_coroutine)


def test_a_destroyed_documents_garbage_is_collected_when_the_server_is_idle(monkeypatch):
    """Panel schedules a full collection 5 s after destroying a page's document, run whatever the
    server is then doing; page.adjust_panel makes it a request to memory.Collector (which runs it
    once the server is idle). Panel must still call it by its module's name for that to hold, and
    schedules nothing whose module is one of the served app's (`bokeh_app_...`, this app's modules
    when served; `app....` here): such a callback raised in the middle of each session's destruction."""
    from panel.io import document

    page.adjust_panel()
    assert "state.schedule_task('gc.collect', _garbage_collect" in inspect.getsource(document._destroy_document)
    assert "startswith('bokeh_app_')" in inspect.getsource(pn.state.schedule_task)
    assert not getattr(document._garbage_collect, "__module__", "").startswith(("bokeh_app_", "app."))
    scheduled = document._garbage_collect
    page.adjust_panel()  # another page: the callback Panel already scheduled, or it warns
    assert document._garbage_collect is scheduled
    monkeypatch.setattr(memory.Collector, "requested", False)
    collected = []
    monkeypatch.setattr(memory.gc, "collect", lambda *args: collected.append(args))
    document._garbage_collect()
    assert memory.Collector.requested and collected == []


def test_the_design_is_computed_once_per_component_class_and_handed_out_as_copies():
    theme = page.Design().theme
    first, _ = page.Design._get_modifiers(pn.widgets.Button(name="x"), theme)
    first["stylesheets"].append("changed.css")
    second, _ = page.Design._get_modifiers(pn.widgets.Button(name="y"), theme)
    assert "changed.css" not in second["stylesheets"] and page.REBOOT in second["stylesheets"]
    assert len([k for k in page.Design._modifiers if k[0] is pn.widgets.Button]) == 1


def test_the_layouts_shim_still_matches_bokehjs():
    """app/static/bokeh_layouts.js defers a root's layout while a message is applied. It relies on
    LayoutDOMView.invalidate_layout handing the request up to the root, which lays out the page at
    once, and on Document.apply_json_patch applying a message; it lays out and waits for only the
    shown components through LayoutDOMView.layoutable_views and has_finished (and Panel's
    TabsView.update_active), lets only those lay out the page when they resize (_after_resize), and
    a plot alone through PlotView._invalidate_layout_if_needed: when a Bokeh or Panel release changes
    any of these, this says so."""
    import re
    from pathlib import Path

    import bokeh
    import panel

    js = (Path(bokeh.__file__).parent / "server" / "static" / "js" / "bokeh.js").read_text()
    assert re.search(r"invalidate_layout\(\) \{\s*// TODO[^\n]*\n[^\n]*\n\s*if \(this\.parent instanceof "
                     r"LayoutDOMView\) \{\s*this\.parent\.invalidate_layout\(\);\s*\}\s*else \{\s*"
                     r"this\.update_layout\(\);\s*this\.compute_layout\(\);", js), \
        "BokehJS lays out differently: revisit app/static/bokeh_layouts.js"
    assert re.search(r"apply_json_patch\(patch, buffers = new Map\(\)\) \{", js)
    assert '"models/layouts/layout_dom":' in js and '"document/document":' in js
    # It lays out only what is shown, through the children a layout walks, and waits for those only
    assert re.search(r"get layoutable_views\(\) \{\s*return this\.child_views\.filter\(\(c\) => c instanceof "
                     r"LayoutDOMView\);", js)
    assert re.search(r"has_finished\(\) \{\s*if \(!super\.has_finished\(\)\) \{\s*return false;\s*\}\s*"
                     r"if \(this\.is_layout_root && !this\._layout_computed\) \{\s*return false;\s*\}\s*"
                     r"for \(const child_view of this\.child_views\) \{", js)
    # a component that resized lays out its root (left out when it is not shown) through _after_resize
    assert re.search(r"after_resize\(\) \{\s*this\._resized = true;\s*if \(this\.update_bbox\(\)\) \{\s*"
                     r"this\._after_resize\(\);", js)
    assert re.search(r"_after_resize\(\) \{\s*super\._after_resize\(\);\s*if \(this\.is_layout_root && "
                     r"!this\._was_built\) \{(?:(?!\n        \}\n).)*this\.compute_layout\(\);", js, re.DOTALL)
    # a plot whose axes changed lays out itself through compute_layout
    assert re.search(r"_invalidate_layout_if_needed\(\) \{(?:(?!\n        \}\n).)*this\.compute_layout\(\);",
                     js, re.DOTALL)
    assert '"models/plots/plot_canvas":' in js
    # a style sheet's text is its element's, written whole by _update, and a layout's writes are
    # update_layout's (it only writes: the reads come after, in compute_layout)
    assert re.search(r"get css\(\) \{\s*return this\.el\.textContent;\s*\}\s*_update\(css\) \{\s*"
                     r"this\.el\.textContent = css;\s*\}", js)
    assert '"core/dom":' in js
    panel_js = (Path(panel.__file__).parent / "dist" / "panel.js").read_text()
    tabs = re.search(r"class TabsView extends [^\n]*\{((?:(?!\n    class ).)*)", panel_js, re.DOTALL)
    assert tabs and re.search(r"\n        update_active\(\) \{", tabs[1]), \
        "Panel's Tabs changed: revisit the shown-tab layout in bokeh_layouts.js"
    # the tabs not shown are taken out of the document after Panel hides them (_after_layout), and
    # their own sheet gets Panel's rule from the Tabs' _update_layout
    assert re.search(r"_after_layout\(\) \{(?:(?!\n        \}\n).)*hide\(child_view\.el\)", tabs[1], re.DOTALL)
    assert re.search(r"_update_layout\(\) \{(?:(?!\n        \}\n).)*for \(const view of this\.child_views\) "
                     r"\{(?:(?!\n        \}\n).)*view\.style\.append\(\":host\", \{ grid_area: \"stack\" \}\);",
                     tabs[1], re.DOTALL), "Panel's Tabs lays out its tabs otherwise: revisit bokeh_layouts.js"


def test_no_model_of_any_tab_needs_the_scripts_the_page_leaves_out():
    """app/page.BOKEH_BUNDLES leaves out BokehJS's WebGL and MathJax bundles: no figure of any tab
    draws with WebGL, no text is MathText and no HTML model holds TeX that Panel would give MathJax
    (the equations are HTML typeset by KaTeX on the server). page.adjust_panel leaves out the polyfill of Panel's
    ESM components: no model of any tab is one."""
    from bokeh.document import Document
    from bokeh.embed.bundle import _use_gl, _use_mathjax
    from bokeh.embed.util import contains_tex_string
    from panel.io.resources import Resources
    from panel.models.esm import ReactiveESM
    from panel.models.markup import HTML

    page.adjust_panel()
    assert not [f for f in Resources(mode="server").js_files if "es-module-shims" in f]

    app = main.App()
    for f in FEATURES:
        app.study.view = f.name
    doc = Document()
    app.template().server_doc(doc)
    models = set(doc.models)
    assert len(models) > 500 and not _use_gl(models) and not _use_mathjax(models)
    assert not [m for m in models if isinstance(m, HTML) and not m.disable_math and contains_tex_string(m.text)]
    assert not [m for m in models if isinstance(m, ReactiveESM)]
    assert set(page.BOKEH_BUNDLES) == {"bokeh", "bokeh-widgets", "bokeh-tables"}


def test_a_message_queued_while_another_batch_is_written_is_still_sent():
    """Panel's writer of queued messages (panel.io.document._dispatch_msgs): a first writer has
    written its batch and is about to resume when a second batch is queued (a second writer
    started); the first resumes first and drops the write flag. Panel's second writer then returned
    without writing, and the batch waited for the page's next change; app/page's does not."""
    import asyncio

    from panel.io import document

    sent = []

    class Socket:
        class write_lock:
            class _block:
                _value = 1

    class Connection:
        _socket = Socket()

        class protocol:
            @staticmethod
            def create(kind, events):
                return events

    connection = Connection()

    class Doc:
        pass

    doc = Doc()

    async def race():
        first = asyncio.get_running_loop().create_future()
        futures = [first]
        document.extra_socket_handlers[Socket] = lambda conn, msg: (sent.append(msg), [futures.pop(0)])[1]
        document.schedule_write_events(doc, [connection], ["one"])
        await asyncio.sleep(0)                      # the first writer writes "one" and waits for it
        first.set_result(None)                      # written: the first writer resumes next...
        later = asyncio.get_running_loop().create_future()
        later.set_result(None)
        futures.append(later)
        document.schedule_write_events(doc, [connection], ["two"])  # ...before the second starts
        for _ in range(5):
            await asyncio.sleep(0)

    page.adjust_panel()
    try:
        asyncio.run(race())
    finally:
        del document.extra_socket_handlers[Socket]
        document._WRITE_MSGS.pop(doc, None)
        document._WRITE_BLOCK.pop(doc, None)
    assert sent == [["one"], ["two"]]

    from tornado.websocket import WebSocketClosedError

    def closed(conn, msg):
        raise WebSocketClosedError()  # tornado's write to a page that has closed

    async def gone():
        logged = []
        asyncio.get_running_loop().set_exception_handler(lambda loop, context: logged.append(context))
        document.extra_socket_handlers[Socket] = closed
        document.schedule_write_events(doc, [connection], ["after the page closed"])
        for _ in range(5):
            await asyncio.sleep(0)
        return logged

    try:
        assert asyncio.run(gone()) == [], "a closed page's queued message is no error"
    finally:
        del document.extra_socket_handlers[Socket]
        document._WRITE_MSGS.pop(doc, None)
        document._WRITE_BLOCK.pop(doc, None)


def test_a_page_that_closes_while_written_to_leaves_no_traceback_and_other_failures_still_show(monkeypatch):
    """app/page.closed_writes_seen: a page closes while Panel writes a message to it (in three parts,
    panel.io.document.dispatch_tornado). Either a part finds the socket closing, and Panel drops the
    parts it had started; or the page's document is destroyed while Panel awaits a part, which
    cancels the wait. The parts never awaited fail with WebSocketClosedError, and asyncio logged
    each ("Task exception was never retrieved") with a traceback; with app/page's write it does
    not, while a write failing otherwise still is. With tornado's own write Panel still leaves them
    (else the adjustment is no longer needed)."""
    import asyncio
    import functools
    import gc
    import inspect

    from bokeh.document import Document
    from panel.io import document
    from tornado.websocket import WebSocketClosedError, WebSocketHandler

    class Writes:
        """tornado's connection of a page that closes during a message: its writes wait, then fail;
        it is closing after `open` writes, and a write then raises at once, as tornado's does."""

        def __init__(self, failure, open):
            self.failure, self.open, self.closed = failure, open, asyncio.Event()

        def is_closing(self):
            return self.open == 0

        def write_message(self, message, binary=False):
            self.open -= 1

            async def write():
                await self.closed.wait()
                raise self.failure

            return asyncio.ensure_future(write())

    class Socket(WebSocketHandler):
        def __init__(self, writes):  # only what WebSocketHandler.write_message reads
            self.ws_connection = writes

    class Connection:
        def __init__(self, writes):
            self._socket = Socket(writes)

        class protocol:
            @staticmethod
            def create(kind, events):
                return types.SimpleNamespace(header_json="{}", metadata_json="{}", content_json="{}", _buffers=[])

    def close_while_written(failure, open):
        """What asyncio logs when a page closes after `open` writes of a message (3: all of it): two
        writes never awaited, the two before the third (2), or the two after the first (3)."""
        logged = []

        async def scenario():
            asyncio.get_running_loop().set_exception_handler(lambda loop, context: logged.append(context))
            doc = Document()
            writes = Writes(failure, open)
            try:
                document.write_events(doc, [Connection(writes)], ["a change"])
            except WebSocketClosedError:  # as panel.io.document.unlocked does, which then schedules it anew
                pass
            document._dispatch_write_task(doc, document._run_write_futures, doc)  # as write_events does, unlocked
            for _ in range(3):
                await asyncio.sleep(0)
            doc.destroy = functools.partial(document._destroy_document, doc)  # as panel.io.application does
            doc.destroy(None)
            writes.closed.set()
            for _ in range(3):
                await asyncio.sleep(0)
            gc.collect()

        asyncio.run(scenario())
        return [(c["message"], type(c["exception"]).__name__) for c in logged]

    page.adjust_panel()
    page.adjust_panel()
    assert WebSocketHandler.write_message.cosymp and not getattr(WebSocketHandler.write_message.__wrapped__,
                                                                 "cosymp", False)
    assert "WebSocketHandler.write_message(socket" in inspect.getsource(document.dispatch_tornado)
    never = "Task exception was never retrieved"
    for open in (2, 3):
        assert close_while_written(WebSocketClosedError(), open) == []
        assert close_while_written(ValueError("not a closed page"), open) == [(never, "ValueError")] * 2
    monkeypatch.setattr(WebSocketHandler, "write_message", WebSocketHandler.write_message.__wrapped__)
    for open in (2, 3):
        assert close_while_written(WebSocketClosedError(), open) == [(never, "WebSocketClosedError")] * 2, \
            "Panel no longer leaves a closed page's writes unretrieved: drop app/page.closed_writes_seen"


def test_a_step_built_ahead_waits_for_the_page_to_have_drawn_the_last(monkeypatch):
    """Steps went every AHEAD_MS while the browser took 150-280 ms to draw each: they queued in the page,
    and a change made meanwhile waited behind them. Now a step's message carries an odd number the page
    answers with number + 1 once idle (PACE_JS), and the next step comes only then, or AHEAD_WAIT_MS
    after the step if no answer came; a late answer to an older step starts nothing."""
    app = main.App()
    later = []
    app._doc = types.SimpleNamespace(session_context=types.SimpleNamespace(session=types.SimpleNamespace(
        connection_count=1)), add_timeout_callback=lambda f, ms: later.append((f, ms)))
    page.Activity.last -= main.AHEAD_IDLE_S
    app._ahead()
    assert app._ahead_done == {"compare"} and app.pace.value % 2 == 1
    [(fallback, ms)] = later
    assert ms == main.AHEAD_WAIT_MS, "no next step before the page answers"
    sent = app.pace.value
    app.pace.value = sent + 1  # the page's answer
    assert later[1:] == [(app._ahead, main.AHEAD_MS)]
    later[1][0]()
    assert app.pace.value == sent + 2 and len(later) == 3, "the next step, waiting for its answer"
    fallback()
    app.pace.value = sent + 1  # a late answer to the first step
    assert len(later) == 3, "nothing started by the first step's fallback or its late answer"
    later[2][0]()
    assert len(later) == 4 and later[3][0] == app._ahead, "no answer: the next step AHEAD_WAIT_MS later"
    assert "requestIdleCallback" in main.PACE_JS and "sent + 1" in main.PACE_JS
    app._stop(None)


def test_tabs_are_built_ahead_one_at_a_time_while_the_page_is_idle_and_start_no_measurement(monkeypatch):
    """App._ahead takes one more step of building the tabs per call (a layout, its joining the page,
    its data drawn), hidden, once the server (every page) has been idle
    AHEAD_IDLE_S: its layout, and the data at hand drawn. Of the computations only the θ lesson's
    runs ahead, when quick and small (Follower.ahead); the long run and the map start on their first
    showing (computed ahead, every page would hold their memory leases), and Work-precision draws
    only this server's measurement of the same inputs (another page's). Gauges is not built ahead.
    Orbits builds the figures of the two-degree-of-freedom shape, hidden."""
    monkeypatch.setattr(workprecision, "MEASURED", {})  # no other test's measurement
    # The lesson quick, as a fast server would have found it (this one's cost is not the subject: on a
    # slow machine modulated's lesson took 37 ms, above QUICK_S).
    monkeypatch.setattr(theta, "LESSON_SECONDS_PER_STEP", dict.fromkeys(SCENES, 1e-9))
    app = main.App()
    names = [f.name for f in FEATURES]
    app._ahead()
    assert not app._ahead_done, "not idle yet"
    page.Activity.last -= main.AHEAD_IDLE_S
    other = main.App()
    app._ahead()
    assert not app._ahead_done, "another page has just been opened"
    other._stop(None)
    page.Activity.last -= main.AHEAD_IDLE_S
    gone = main.App()
    gone._doc = types.SimpleNamespace(session_context=types.SimpleNamespace(session=types.SimpleNamespace(
        connection_count=0)))
    page.Activity.last -= main.AHEAD_IDLE_S
    gone._ahead()
    assert not gone._ahead_done, "a page whose browser has gone builds nothing ahead (its session lingers)"
    gone._stop(None)
    app._ahead()
    assert app._ahead_done == {"compare"} and len(app.tabs[0]) == 1, "one step at a time: Orbits' data"
    for _ in range(4 * len(FEATURES)):
        app._ahead()
    assert next(app._ahead_steps, None) is None, "every step taken"
    assert app._ahead_done == {f.name for f in FEATURES if f.ahead} == set(names) - {"gauges"}
    assert [len(app.tabs[i]) for i in range(len(names))] == [n != "gauges" for n in names]
    assert app.tabs.active == names.index("compare") and app.study.view == "compare"
    lesson = app.states["theta"]
    assert lesson.results is not None and lesson.sweep is not None and not app.views["theta"]._stale, \
        "the θ lesson (quick, and its lease under AHEAD_BYTES) is computed and drawn ahead"
    assert not app.states["long"].data and app.states["map"].result is None
    measure = app.states["workprecision"].measure
    assert not measure.rows and not measure.running and app.states["gauges"].results is None
    assert not any(app.views[n]._stale for n in ("structure", "cloud", "play"))
    orbits = app.views["compare"]
    assert len(orbits.grids) == 2 and [g.visible for g in orbits.grids] == [True, False]
    app.study.view = "theta"
    assert lesson.results is not None and lesson.sweep is not None, "computed when first shown"
    app.study.view = "compare"
    app.study.scene = "charged"
    assert [g.visible for g in orbits.grids] == [False, True], "the charged particle's figures were ready"
    shown = lesson.results
    lesson.quick = lambda: False  # what this server has seen decides it (LESSON_SECONDS_PER_STEP): here, not quick
    lesson.ahead()
    assert lesson.results is shown, "a lesson not expected to be quick waits for its tab"
    app._stop(None)


def test_a_spare_builds_its_tabs_layouts_while_it_waits_and_its_page_only_has_them_join(monkeypatch, caplog):
    """A session built as a spare (page.Spares) builds the layout of each tab built ahead, one per step,
    while the server is idle (App._layouts_ahead): nothing joins its document, so the page's first
    document stays as small. Its page's building ahead then has no layout step left, and its load
    stops the spare's steps, as its end does."""
    from bokeh.document import Document
    from panel.io.state import set_curdoc

    doc = Document()
    scheduled = []
    monkeypatch.setattr(doc, "add_timeout_callback", lambda callback, ms: scheduled.append(callback))
    held = memory.BUDGET.used  # the leases of pages made before
    building = page.Spares._building.set(True)
    try:
        with set_curdoc(doc):
            app = main.App()
    finally:
        page.Spares._building.reset(building)
    assert scheduled == [app._layouts_ahead]
    ahead = [f.name for f in FEATURES if f.ahead]
    page.Activity.touch()
    app._layouts_ahead()
    assert [n for n in ahead if app.views[n].built] == ["compare"], "not idle: nothing built"
    page.Activity.last -= main.AHEAD_IDLE_S
    with caplog.at_level("INFO", logger=page.LOG.name):
        for k in range(len(ahead) - 1):
            app._layouts_ahead()
            assert sum(app.views[n].built for n in ahead) == k + 2, "one layout a step"
        assert len(scheduled) == len(ahead) + 1 and not [r for r in caplog.records if r.name == page.LOG.name]
        remembering = [s for s in app.states.values() if isinstance(s, Job) and s.KEEP]
        assert sorted(s.KIND for s in remembering) == ["long run", "stability map"]
        page.Activity.touch()
        app._layouts_ahead()
        assert not jobs.REMEMBERED, "not idle: nothing computed"
        page.Activity.last -= main.AHEAD_IDLE_S
        app._layouts_ahead()  # without a server a computation runs to its end in the call
        assert [kind for kind, _ in jobs.REMEMBERED] == ["long run"], "one computation a step"
        computed = app._remembering[-1]
        computed.running = True
        app._layouts_ahead()
        assert len(jobs.REMEMBERED) == 1, "nothing while one of them runs"
        computed.running = False
        app._layouts_ahead()
        assert sorted(kind for kind, _ in jobs.REMEMBERED) == ["long run", "stability map"]
        assert not app.states["long"].data and app.states["map"].result is None and not any(
            j.running for j in app.jobs), "in jobs of its own: the page's (its spinner's) stay idle"
        assert computed.study is not app.study and app.study.message is None, "on a study of their own"
        assert len(scheduled) == len(ahead) + 5
        doc._session_context = lambda: types.SimpleNamespace(id="spare-id")  # for the log line
        app._layouts_ahead()
        assert page.SPARE_READY % "spare-id" in caplog.text and len(scheduled) == len(ahead) + 5
        assert app._remembering == [] and computed._closed and computed.study._closed, "released when done"
        own = app.study._held.nbytes + (app.study.carry._held.nbytes if app.study.carry._held else 0)
        assert memory.BUDGET.used == held + own, "no lease held but the page's own comparison's and its loops'"
    assert doc.roots == [] and len(doc.models) == 0, "the spare's document is not touched"
    other = main.App()
    other.study.view = "long"
    assert other.states["long"].data.keys() == computed.data.keys() and other.states["long"].data
    assert "by this server" in other.states["long"].status, "another page with the defaults recalls it"
    other.study.view = "map"
    assert "by this server" in other.states["map"].status
    other._stop(None)

    def layout_steps(a):
        return sum(getattr(step, "__qualname__", "").endswith("__panel__") for step in a._ahead_work())

    assert layout_steps(app) == 0, "the page only has them join"
    plain = main.App()
    assert layout_steps(plain) == len(ahead) - 1, "a page's own session builds every layout ahead but the one it shows"
    ended = []
    for end, call in (("_flush", lambda a: a._flush()), ("_stop", lambda a: a._stop(None))):
        spare = main.App()
        spare._doc = Document()
        monkeypatch.setattr(spare._doc, "add_timeout_callback", lambda callback, ms: scheduled.append(callback))
        scheduled.clear()
        call(spare)
        spare._layouts_ahead()
        assert scheduled == [] and not spare.views["structure"].built, f"after {end}: nothing more"
        ended.append(spare)
    for a in (app, plain, *ended):
        a._stop(None)


def test_a_spares_computation_ahead_that_fails_is_tried_once_and_said_only_in_the_log(monkeypatch, caplog):
    """A computation ahead that fails (or is refused) is not retried every step (it was, every 50 ms,
    with an error posted each time), and what it says goes to the server's log, not to the page the
    spare becomes; a spare's page that stops releases the computation under way."""
    from bokeh.document import Document

    from app.features import longrun

    calls = []

    def fails(self, inputs, run):
        calls.append(inputs)
        raise RuntimeError("boom")

    monkeypatch.setattr(longrun.LongRun, "_compute", fails)
    app = main.App()
    app._doc = Document()  # without a session: a computation runs to its end in the call
    monkeypatch.setattr(app._doc, "add_timeout_callback", lambda callback, ms: None)
    for view in app.views.values():
        view.__panel__()
    page.Activity.last -= main.AHEAD_IDLE_S
    with caplog.at_level("INFO", logger=page.LOG.name):
        for _ in range(2):
            app._layouts_ahead()
        app._doc._session_context = lambda: types.SimpleNamespace(id="spare-id")  # for the log line
        for _ in range(3):
            app._layouts_ahead()
    assert len(calls) == 1 and [kind for kind, _ in jobs.REMEMBERED] == ["stability map"]
    assert page.SPARE_SAID % "long run failed: RuntimeError: boom" in caplog.text
    assert page.SPARE_READY % "spare-id" in caplog.text and app.study.message is None
    jobs.REMEMBERED.clear()
    again = main.App()
    monkeypatch.setattr(memory.BUDGET, "used", memory.BUDGET.cap)
    assert not again._remember_ahead() and again._remembering == [], "no memory free: nothing"
    monkeypatch.setattr(memory.BUDGET, "used", 0)
    started = main.App()
    monkeypatch.setattr(longrun.LongRun, "request", lambda self: setattr(self, "running", True))
    assert started._remember_ahead() and started._remembering[-1].running
    running = started._remembering[-1]
    started._stop(None)
    assert running._closed and all(j._closed for j in started._remembering)
    for a in (app, again):
        a._stop(None)


def test_building_a_pages_session_is_no_change_its_load_is(monkeypatch):
    """A session built ahead of its page (a spare, app/page.Spares) counted as a page's change: every
    page's building ahead then waited AHEAD_IDLE_S more, and a tab clicked 3 s after its page was
    often not built. The page's request and its load count (served, onload runs at the load)."""
    loads = []
    monkeypatch.setattr(pn.state, "onload", lambda callback, threaded=False: loads.append(callback))
    page.Activity.last = before = page.Activity.last - 10
    app = main.App()
    assert page.Activity.last == before and loads == [app._flush]
    app._flush()
    assert page.Activity.last > before
    app._stop(None)


def test_work_precision_is_drawn_ahead_with_the_servers_measurement_of_the_same_inputs(monkeypatch):
    """Another page measured these inputs: a page building its tabs ahead draws that measurement in
    its hidden Work-precision tab (a class opening the tab sees it at once); nothing is measured ahead."""
    rows = [{"kind": "cosymp", "solver": "midpoint", "h": 0.1, "T": 50.0, "rtol": math.nan, "wall_s": 1e-4,
             "error": 1e-3, "H_ext_max_abs": 1e-4, "det_max_dev": 0.0, "steps": 500, "status": "ok", "order": 2,
             "preserves": "symplectic", "reference": "exact flow", "reference_uncertainty": 0.0}]
    monkeypatch.setattr(workprecision, "MEASURED", {})
    app = main.App()
    measure, view = app.states["workprecision"].measure, app.views["workprecision"]
    workprecision.MEASURED[workprecision.key(measure._inputs())] = (rows, datetime.datetime.now())
    page.Activity.last -= main.AHEAD_IDLE_S
    for _ in range(4 * len(FEATURES)):
        app._ahead()
    assert measure.rows == rows and not measure.running and "by this server" in measure.status
    assert not view._stale and view.wp_box.visible
    assert list(view.wp_plots[0].points.data["x"]) == [1e-4]
    app._stop(None)


def test_a_lesson_leasing_more_than_the_ahead_bound_waits_for_its_tab(monkeypatch):
    """Follower.ahead computes only under AHEAD_BYTES: every open page would hold the lease."""
    monkeypatch.setattr(theta, "LESSON_SECONDS_PER_STEP", dict.fromkeys(SCENES, 1e-9))  # quick, as above
    app = main.App()
    lesson = app.states["theta"]
    need = lesson._bytes(lesson._inputs())
    assert lesson.quick() and lesson.results is None
    monkeypatch.setattr(base, "AHEAD_BYTES", need - 1)
    lesson.ahead()
    assert lesson.results is None
    monkeypatch.setattr(base, "AHEAD_BYTES", need)
    lesson.ahead()
    assert lesson.results is not None
    app._stop(None)


def test_a_session_built_ahead_of_its_page_serves_its_stylesheets_locally():
    """Panel's warm reuse_sessions (app/warmup.py) and serve_locally: Panel builds a reused page's
    session without writing its HTML, so nothing sets the template variable its stylesheet links are
    made from; serve_locally sets it before any model is made. Only useful while Panel builds warm sessions this way and reads
    that variable: when a release changes either, this says so."""
    import inspect

    from bokeh.document import Document
    from panel.io import server
    from panel.io.resources import CDN_DIST
    from panel.io.state import set_curdoc
    from panel.reactive import Reactive

    assert "create_session_if_needed" in inspect.getsource(server.DocHandler.get)
    assert "doc._template_variables['dist_url']" in inspect.getsource(Reactive._get_properties)
    def links(local):
        doc = Document()
        context = types.SimpleNamespace(session=None, server_context=None, id="x",
                                        request=types.SimpleNamespace(arguments={}, headers={}, cookies={}))
        doc._session_context = lambda: context  # a weak reference in a served document
        with set_curdoc(doc):
            if local:
                page.serve_locally()
            return [s.url for s in pn.widgets.Button(name="x").get_root(doc).stylesheets if hasattr(s, "url")]

    assert [u for u in links(False) if u.startswith(CDN_DIST)], "without serve_locally, links to the CDN"
    local = links(True)
    assert local and not [u for u in local if u.startswith(CDN_DIST)], local
    assert not [p for p in pathlib.Path(main.__file__).parent.rglob("*.py") if "Divider(" in p.read_text()], \
        "Panel's Divider links its stylesheet from the CDN"


def test_a_pages_stylesheet_addresses_are_patched_from_its_documents_models(monkeypatch):
    """page.sheets_from_the_document: Panel's patch of the stylesheet addresses of a page's roots,
    which Panel runs before writing the page's HTML, finds the stylesheets among the document's
    models instead of walking every model's references from each root, and patches them as Panel's
    walk does: every CDN address local. Only right while Panel's page writer calls the patch by the
    name it is installed under: when a release changes that, this says so."""
    from bokeh.document import Document
    from bokeh.model import Model
    from bokeh.models import ImportedStyleSheet
    from panel.io import resources, server

    page.adjust_panel()
    assert server.patch_model_css.cosymp and not getattr(server.patch_model_css.__wrapped__, "cosymp", False)
    assert "patch_model_css(root" in inspect.getsource(server.server_html_page_for_session)
    assert "root.select({'type': ImportedStyleSheet})" in inspect.getsource(resources.patch_model_css)
    doc = Document()
    roots = [pn.Column(pn.widgets.Button(name=f"b{i}"), pn.pane.Markdown(f"m{i}")).get_root(doc) for i in range(2)]
    for root in roots:
        doc.add_root(root)
    cdn = [s for s in doc.models if isinstance(s, ImportedStyleSheet) and s.url.startswith(resources.CDN_DIST)]
    assert len(cdn) >= 2, "no stylesheet linked from the CDN to patch"
    walked = []
    monkeypatch.setattr(Model, "references", lambda self: walked.append(self) or set())
    for root in roots:
        server.patch_model_css(root, resources.LOCAL_DIST)
    assert not walked
    assert all(s.url.startswith(resources.LOCAL_DIST) for s in cdn), [s.url for s in cdn]


def test_a_page_whose_browser_has_gone_stops_at_the_second_look():
    """App._watch (every GONE_MS after the page has loaded): a page seen without a connection twice in a
    row stops (its runs cancelled, its leases given back) and its session is discarded (as the server's
    check for unused sessions would, half a minute later); once is not enough (a connection being
    replaced), and the first page's session, which Panel keeps for good, is not waited for."""
    app = main.App()
    removed = []
    session = types.SimpleNamespace(connection_count=1)
    app._doc = types.SimpleNamespace(session_context=types.SimpleNamespace(session=session),
                                     remove_periodic_callback=removed.append)
    app._gone, app._watcher = False, "watcher"
    app._watch()
    session.connection_count = 0
    app._watch()
    assert not app._stopped and not removed, "gone once"
    session.connection_count = 1
    app._watch()
    session.connection_count = 0
    app._watch()
    assert not app._stopped, "back, then gone once again"
    from bokeh.server.contexts import ApplicationContext

    assert list(inspect.signature(ApplicationContext._discard_session).parameters) == \
        ["self", "session", "should_discard"], "Bokeh discards sessions another way now: revisit App._discard"
    discarded = []

    async def discard_session(s, should_discard):
        discarded.append((s, should_discard(s)))

    app._doc.session_context.server_context = types.SimpleNamespace(
        application_context=types.SimpleNamespace(_discard_session=discard_session))
    session.expiration_blocked = False

    async def look(call):
        call()
        await asyncio.sleep(0)

    asyncio.run(look(app._watch))
    assert app._stopped and removed == ["watcher"] and app.study._closed
    assert discarded == [(session, True)], "its session is discarded, not left to the server's check"
    session.expiration_blocked = True
    asyncio.run(look(app._discard))
    assert len(discarded) == 1, "a session whose expiration is blocked (the one Panel keeps) is not"


def test_a_scene_change_drops_another_scenes_long_run_and_map_and_the_shown_tab_computes_the_new_one():
    """The Long run and the Stability map show only the study's scene: a scene change stops the run
    under way and drops the old data; the shown tab then runs the new scene (after the stopped run:
    Job.cancel and a request after it), a hidden one when it is next shown."""
    app = main.App()
    app.study.scene = "damped"
    lr = app.states["long"]
    switched = []

    def switch(event):  # mid-run (the run is synchronous without a server): change the scene
        if event.new > 0 and not switched:
            switched.append(True)
            app.study.scene = "decaying"

    lr.param.watch(switch, "progress")
    drawn = []  # (scene of the run, scene shown) of each partial result drawn
    partial = lr._partial
    lr._partial = lambda inputs, data: (drawn.append((inputs[4], app.study.scene)), partial(inputs, data))
    app.study.view = "long"
    assert switched and not lr.running
    assert ("damped", "decaying") not in drawn and ("decaying", "decaying") in drawn, \
        "the stopped run's last envelopes are dropped (Job.discard)"
    assert lr.setting.startswith("decaying:") and lr.data and lr.status.startswith("done"), (lr.setting, lr.status)
    app.study.view = "map"
    assert app.states["map"].result.plan.scene == "decaying"
    app.study.view = "compare"
    app.study.scene = "damped"
    assert not lr.data and not lr.setting and app.states["map"].result is None, "the old scene's data goes"
    app.study.view = "map"
    assert app.states["map"].result.plan.scene == "damped"
    app._stop(None)


def test_a_page_without_settings_gets_the_spare_session_and_a_link_with_settings_its_own(monkeypatch):
    """page.Spares.session_id, which Panel's handler of a page's request calls (once page.adjust_panel
    has run) for the id of the session it builds while the page loads: the spare's for a request
    without settings (its build then finds it built), kept from the check for unused sessions until
    its page has loaded (Spares.loaded) or HANDED_S have passed; a new id for a link with settings,
    or when the spare was discarded meanwhile.
    The served flow, from the spare's build to its page, is test_app_e2e's."""
    from panel.io import server

    assert server.generate_session_id == page.Spares.session_id and server.DocHandler.get.cosymp
    source = inspect.getsource(server.DocHandler.get.__wrapped__)
    assert "generate_session_id(" in source and "create_session_if_needed" in source, \
        "Panel's warm sessions no longer work this way: revisit app/page.Spares"
    monkeypatch.setattr(page.Spares, "HANDED_S", 0.05)
    monkeypatch.setattr(page.Spares, "ready", {})
    monkeypatch.setattr(page.Spares, "handed", {})
    unblocked = []
    spare = types.SimpleNamespace(id="spare-id", unblock_expiration=lambda: unblocked.append("spare"))
    loads = types.SimpleNamespace(id="loads-id", unblock_expiration=lambda: unblocked.append("loads"))
    context = type("Context", (), {"_sessions": {"spare-id": spare, "loads-id": loads}})()
    plain = (context, "/app")

    async def ask(key):
        asking = page.Spares._asking.set(key)
        try:
            return page.Spares.session_id()
        finally:
            page.Spares._asking.reset(asking)

    async def scenario():
        page.Spares.ready[plain] = "spare-id"
        with_settings = await ask(None)
        assert with_settings != "spare-id" and page.Spares.ready == {plain: "spare-id"}
        assert await ask(plain) == "spare-id" and page.Spares.ready == {}
        assert unblocked == [], "kept until its browser has had time to connect"
        again = await ask(plain)
        assert again not in ("spare-id", with_settings), "one page per spare"
        await asyncio.sleep(0.1)
        assert unblocked == ["spare"] and page.Spares.handed == {}
        page.Spares.ready[plain] = "loads-id"
        assert await ask(plain) == "loads-id"
        page.Spares.loaded(loads)
        page.Spares.loaded(spare)
        assert unblocked == ["spare", "loads"], "a spare whose page has loaded is kept no longer"
        await asyncio.sleep(0.1)
        assert unblocked == ["spare", "loads"], "and is let go once"
        page.Spares.ready[plain] = "discarded-id"
        assert await ask(plain) != "discarded-id"

    asyncio.run(scenario())


def test_a_components_parameters_are_writable_for_a_moment_as_panel_makes_them_and_flagged_again_after():
    """app/page.editable stands in for Panel's edit_readonly wherever a page's changes call it, and
    does what Panel's does: inside, every parameter can be set (read-only and constant ones too);
    after, also after an error, the flags are as Panel's leaves them (as before, where nothing was
    set; param copies a parameter to the instance when it is first set, and that copy keeps the
    flags it had then, with either). It only touches the flagged parameters."""
    page.adjust_panel()
    for name in page.EDITS_READONLY:
        assert importlib.import_module(name).edit_readonly is page.editable, name
    source = inspect.getsource(page.PANEL_EDIT_READONLY)
    assert "p.readonly = False" in source and "p.constant = False" in source, "Panel's edit_readonly changed"

    def used(edit, set_flagged, fail):
        widget = pn.widgets.IntSlider(start=0, end=10, value=3)

        def flags():
            return {n: (p.readonly, p.constant) for n, p in widget.param.objects("existing").items()}

        before = flags()
        flagged = [n for n, (readonly, constant) in before.items() if readonly or constant]
        assert flagged, "a widget with read-only or constant parameters"
        try:
            with edit(widget):
                assert not any(readonly or constant for readonly, constant in flags().values())
                if set_flagged:
                    widget.param.update(**{n: getattr(widget, n) for n in flagged})
                if fail:
                    raise RuntimeError
        except RuntimeError:
            pass
        return before, flags()

    for set_flagged in (False, True):
        for fail in (False, True):
            before, after = used(page.editable, set_flagged, fail)
            assert after == used(page.PANEL_EDIT_READONLY, set_flagged, fail)[1]
            if not set_flagged:
                assert after == before


def held_comparisons(monkeypatch, gate):
    """Comparisons that wait for the gate in their thread (none computed in a change's handler)."""
    from app import study

    real = study.run_pair

    def held(*args, **kwargs):
        gate.wait(30)
        return real(*args, **kwargs)

    monkeypatch.setattr(study, "run_pair", held)
    monkeypatch.setattr(study.Study, "quick", lambda self: False)


def test_the_report_waits_for_the_comparison_under_way_saying_so_and_takes_its_runs(monkeypatch):
    """Download report while a comparison computes: the report computed it again, in the server's
    thread (no page answered meanwhile, the button said nothing: 20 s for kapitza at T = 5000). It
    waits for the page's own, the button saying so, and takes its runs."""
    from app import study

    gate = threading.Event()
    real_report = study.scene_report
    given = []

    def report(*args, computed=None, **kwargs):
        given.append(computed)
        return real_report(*args, computed=computed, **kwargs)

    async def scenario():
        app = main.App()
        app.template()
        label = app._download.label
        held_comparisons(monkeypatch, gate)
        monkeypatch.setattr(study, "scene_report", report)
        app.study.T = 30.0
        task = asyncio.ensure_future(app._report())
        await asyncio.sleep(0.3)
        assert not task.done() and app._download.label == "Report: waiting for this comparison"
        gate.set()
        text = (await task).read().decode()
        assert "--T 30 " in text and app.study.results.T == 30.0
        assert given and given[0] is not None, "the page's runs, not computed again"
        assert app._download.label == label
        notes = []
        app._notify = lambda level, text: notes.append(text)
        gate.clear()
        app.study.T = 35.0
        task = asyncio.ensure_future(app._report())
        await asyncio.sleep(0.3)
        app.study.other = "gauss4"  # changed while it waits: the report is of what is shown, and says so
        gate.set()
        text = (await task).read().decode()
        assert "--vs gauss4" in text and "--T 35 " in text
        assert notes == ["report: of the settings shown now, changed since Download was clicked"]
        app._stop(None)

    asyncio.run(scenario())


def test_a_second_click_gets_the_report_being_made_and_the_button_its_label_back(monkeypatch):
    """Each click ran its own wait; the last to end put back the label the first had set ('Report:
    waiting ...' for good). A second click now waits for the first's report."""
    gate = threading.Event()
    made = []
    real_rendered = main.rendered_report

    def rendered(*args):
        made.append(args[0].filename)
        return real_rendered(*args)

    async def scenario():
        app = main.App()
        app.template()
        held_comparisons(monkeypatch, gate)
        monkeypatch.setattr(main, "rendered_report", rendered)
        app.study.T = 30.0
        first = asyncio.ensure_future(app._report())
        await asyncio.sleep(0.2)
        second = asyncio.ensure_future(app._report())
        await asyncio.sleep(0.2)
        gate.set()
        a, b = (await first).read(), (await second).read()
        assert a == b and len(made) == 1 and app._download.label == main.REPORT_LABEL
        app._stop(None)

    asyncio.run(scenario())


def test_a_report_reads_the_page_on_the_loop_not_in_its_thread(monkeypatch):
    """The executor busy (other pages' reports), the thread started late and read the study then:
    the file named for midpoint held rk4's report (helper 33). It reads the inputs taken on the loop."""
    async def scenario():
        app = main.App()
        app.template()
        s = app.study
        loop = asyncio.get_running_loop()
        gate = threading.Event()
        busy = [loop.run_in_executor(None, gate.wait, 30) for _ in range(64)]
        task = asyncio.ensure_future(app._report())
        await asyncio.sleep(0.1)
        name, method = app._download.filename, s.method
        s.method = "rk8"
        gate.set()
        await asyncio.gather(*busy)
        text = (await task).read().decode()
        assert name == f"cosymp-{s.scene}-{method}.html" and f"--method {method} " in text
        app._stop(None)

    asyncio.run(scenario())


def test_a_report_of_a_page_closed_while_it_waits_is_not_made(monkeypatch):
    gate = threading.Event()
    made = []

    async def scenario():
        app = main.App()
        app.template()
        held_comparisons(monkeypatch, gate)
        monkeypatch.setattr(main, "rendered_report", lambda *args: made.append(args))
        app.study.T = 30.0
        task = asyncio.ensure_future(app._report())
        await asyncio.sleep(0.2)
        app._stop(None)
        gate.set()
        assert "No report: the page was closed" in (await task).read().decode() and made == []

    asyncio.run(scenario())


def test_what_a_report_computes_beyond_the_pages_runs_holds_its_memory(monkeypatch):
    """A reference the budget refused the page was computed by the report anyway, in a thread, with
    no lease; now the report leases it (refused alike: a message and a file saying so), and gives it
    back when done."""
    from app import study
    from cosymp.report import scene as report_scene

    computed = []
    real = report_scene.reference_states
    monkeypatch.setattr(report_scene, "reference_states", lambda *a, **k: computed.append(a) or real(*a, **k))

    async def scenario():
        app = main.App()
        app.template()
        notes = []
        app._notify = lambda level, text: notes.append((level, text))
        s = app.study
        s.scene = "kapitza"
        while s.running or s.late.running:
            await asyncio.sleep(0.02)
        inputs = study.report_inputs(s)
        assert inputs.computed is not None and inputs.bytes() == 0, "the page's runs, measured: nothing more"
        unmeasured = inputs._replace(computed=[(dataclasses.replace(c, error=None), f) for c, f in inputs.computed])
        need = unmeasured.bytes()
        assert need == study.reference_bytes(inputs.setups[0], inputs.h, inputs.T) > 0
        monkeypatch.setattr(study, "report_inputs", lambda study_: unmeasured)
        monkeypatch.setattr(main, "report_inputs", lambda study_: unmeasured)
        monkeypatch.setattr(memory, "BUDGET", memory.MemoryBudget(cap_bytes=need // 2))
        text = (await app._report()).read().decode()
        assert text.startswith("<!DOCTYPE html><html><body><p>No report: this report needs about") and computed == []
        assert notes and notes[-1][0] == "error"
        budget = memory.MemoryBudget(cap_bytes=4 * need)
        monkeypatch.setattr(memory, "BUDGET", budget)
        text = (await app._report()).read().decode()
        assert "No report" not in text and len(computed) == 1 and budget.used == 0
        app._stop(None)

    asyncio.run(scenario())
