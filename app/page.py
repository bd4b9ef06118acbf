"""The page's plumbing: Panel and BokehJS adjusted so that a live page answers at once.

Each adjustment names what it saves; tests/test_app_main.py fails when a Panel or Bokeh release
changes what one relies on.
"""
import asyncio
import contextlib
import contextvars
import functools
import importlib
import logging
import time
from typing import ClassVar

import panel as pn
from bokeh.resources import Resources
from bokeh.util.token import generate_jwt_token, generate_session_id
from panel.io import document, server
from panel.io.document import unlocked
from panel.io.resources import LOCAL_DIST
from panel.io.state import set_curdoc
from panel.models.esm import ReactiveESM
from panel.reactive import Syncable
from panel.theme import Bootstrap
from panel.util import parameters
from tornado.websocket import WebSocketClosedError, WebSocketHandler

from . import graph, messages, properties
from .memory import Collector

REBOOT = "app/static/bootstrap_reboot.css"  # Bootstrap's Reboot section, verbatim (see Design)
# BokehJS and Panel's views adjusted in the page (served from app/static by the server; see each file).
SCRIPTS = {"cosymp_bokeh_reads": "app/static/bokeh_reads.js", "cosymp_bokeh_layouts": "app/static/bokeh_layouts.js",
           "cosymp_bokeh_sends": "app/static/bokeh_sends.js", "cosymp_bokeh_quiet": "app/static/bokeh_quiet.js"}


class Design(Bootstrap):
    """Panel's Bootstrap design with Bootstrap's Reboot (its element defaults: 81 rules) in each
    component's shadow root instead of the whole of bootstrap.min.css (2,490 rules; no other rule of
    it matches an element there). The page keeps the whole sheet. Panel renders each component in
    a shadow root with its own copy of the design's sheets, and a style recalculation matches every
    element of a root against all of its rules: with the whole sheet, each of the many that BokehJS
    forces by reading the layout back cost 1-3 ms, and a scene change a third of its time."""

    _modifiers: ClassVar[dict] = {}

    @classmethod
    def _get_modifiers(cls, viewable, theme=None, isolated=True):
        """Memoized: they depend only on the component's class, the theme, isolation and whether a
        server runs, yet Panel recomputes them (a filesystem check per stylesheet path) on every
        property a component sends, about 20 ms of each scene change."""
        doc = pn.state.curdoc
        key = (type(viewable), type(theme) if isinstance(theme, pn.theme.Theme) else theme, isolated,
               bool(doc is not None and doc.session_context))
        if key not in cls._modifiers:
            modifiers, children = super()._get_modifiers(viewable, theme, isolated)
            whole = set(cls._resources["css"].values())
            if "stylesheets" in modifiers:
                modifiers["stylesheets"] = [REBOOT if s in whole else s for s in modifiers["stylesheets"]]
            cls._modifiers[key] = (modifiers, children)
        modifiers, children = cls._modifiers[key]
        # Copies: Panel replaces the stylesheets of what it gets with its documents' sheet models.
        return ({k: list(v) if isinstance(v, list) else v for k, v in modifiers.items()},
                {k: list(v) if isinstance(v, list) else v for k, v in children.items()})


def in_one_message(change_event):
    """Panel's handling of a change from the page, with every model change it causes sent in one
    message: Panel sent one per component (a scene change: the h and T boxes, the controls, each
    equation...), and BokehJS lays out the whole page after each message that changes a layout."""

    @functools.wraps(change_event)
    def handled(self, doc):
        with set_curdoc(doc), unlocked():
            change_event(self, doc)

    handled.cosymp = True
    return handled


# The BokehJS bundles the page loads: not its WebGL or MathJax ones (2 MB of the page's 5.5, about
# 100 ms of its first load), which no figure or text of the app uses (the equations are KaTeX's,
# typeset on the server; tests/test_app_main.py checks that no model of the page needs them).
# Panel's own bundle needs the tables bundle.
BOKEH_BUNDLES = ["bokeh", "bokeh-widgets", "bokeh-tables"]


def no_stranded_messages(dispatch_msgs):
    """Panel's writer of the messages it queued while a page's websocket was busy, without a race
    that left a message unsent until the page's next change (under load, a slider move's plots
    arrived a minute late, with the next move). The writer drops the document's write flag when it
    has written its batch; a batch queued while it wrote sets the flag and starts a second writer,
    which finds the flag gone if the first resumed before it ran, and returns without writing. Here
    a writer that finds messages queued writes them. A page that has closed when its queued messages
    are written (tornado's write raises at once) has nothing left to write to: that is no error (it
    was logged with a traceback, "Task exception was never retrieved")."""

    @functools.wraps(dispatch_msgs)
    async def dispatch(doc):
        if document._WRITE_MSGS.get(doc):
            document._WRITE_BLOCK[doc] = True
        with contextlib.suppress(WebSocketClosedError):
            await dispatch_msgs(doc)

    dispatch.cosymp = True
    return dispatch


class _Sheets:
    """A root as Panel's patch of stylesheet addresses uses it (`document`, `select` by type), its
    models found among the document's: Bokeh keeps every model of a document in a dict."""

    def __init__(self, root):
        self.document = root.document

    def select(self, selector):
        return [m for m in self.document.models if isinstance(m, selector["type"])]


def sheets_from_the_document(patch_model_css):
    """Panel's patch of the stylesheet addresses of each root of a page's document, run before the
    page's HTML is written, without walking every model's references from the root: that walk took
    the server's one thread 0.4-0.5 s a page (py-spy: 103 of 122 samples of the handler of a
    page's request; its 25 static files waited). A root outside any document is walked as before."""

    @functools.wraps(patch_model_css)
    def patched(root, dist_url):
        return patch_model_css(root if root.document is None else _Sheets(root), dist_url)

    patched.cosymp = True
    return patched


def closed_writes_seen(write_message):
    """tornado's write of a message to a page's websocket, whose failure because the page has closed
    counts as seen. Panel writes each message in three or more parts
    (panel.io.document.dispatch_tornado) and awaits them later, logging such a failure as a warning,
    but a page that closes meanwhile leaves parts it never awaits: those written before a part that
    finds the socket closing (dispatch_tornado then raises, and Panel drops the parts it had
    started), and those after the part it was awaiting when the page's document is destroyed (which
    cancels the awaiting task). Each failed with WebSocketClosedError, and asyncio logged it,
    never retrieved, with a traceback ("Task exception was never retrieved ...
    WebSocketClosedError"): 8 of 12 pages closed in their first seconds left one. Bokeh awaits its
    own writes (its handler's write_message calls this one); any other failure is logged as before."""

    @functools.wraps(write_message)
    def write(self, message, binary=False):
        future = write_message(self, message, binary)
        future.add_done_callback(_seen_if_closed)
        return future

    write.cosymp = True
    return write


def _seen_if_closed(future):
    """A write that failed because its page closed, marked as retrieved (what future.exception()
    does; calling it would mark every failure)."""
    if not future.cancelled() and isinstance(future._exception, WebSocketClosedError):
        future._log_traceback = False


@contextlib.contextmanager
def editable(parameterized):
    """Panel's edit_readonly (a component's parameters writable while Panel sets them from the page
    or its own bookkeeping), touching only the parameters that are read-only or constant. Panel's
    sets both flags of every parameter, and back, and param handles each set as a change of that
    parameter (1.3 us here): 0.2 ms for a widget (33 parameters, 2 of them flagged; 0.04 ms here).
    Counted in the server, the sidebar's sliders alone entered Panel's 626 times in 18 scene changes
    and a page's load (152 ms); a scene change's handling takes about 45 ms there."""
    flagged = [(p, p.readonly, p.constant) for p in parameterized.param.objects("existing").values()
               if p.readonly or p.constant]
    for p, _, _ in flagged:
        p.readonly = p.constant = False
    try:
        yield
    finally:
        for p, readonly, constant in flagged:
            p.readonly, p.constant = readonly, constant


PANEL_EDIT_READONLY = parameters.edit_readonly  # Panel's, which `editable` replaces
EDITS_READONLY = ("panel.util.parameters", "panel.util", "panel.reactive", "panel.io.state", "panel.io.location",
                  "panel.io.server", "panel.widgets.base", "panel.widgets.slider")
"""The modules of Panel whose edit_readonly a page's changes call (each imported it by name)."""


class Activity:
    """When a page of this server last changed (time.monotonic()). Work done ahead (the tabs built
    hidden, a spare session) waits until every page has been idle a while, so that pages in use
    never wait for it. Held here, in an imported module: main.py runs anew for each page, so a class
    of it saw that page's changes only."""

    last = 0.0

    @classmethod
    def touch(cls, *events):
        cls.last = time.monotonic()

    @classmethod
    def idle(cls, seconds):
        return time.monotonic() - cls.last >= seconds


# Logged under Panel's logger (PANEL_LOG_LEVEL=info shows it beside Panel's session lines).
LOG = logging.getLogger("panel.cosymp")
SPARE_BUILT = "cosymp: spare session %s built in %.2f s"
SPARE_HANDED = "cosymp: a page got spare session %s"
SPARE_READY = "cosymp: spare session %s has built its tabs' layouts and has nothing more to compute ahead"
SPARE_SAID = "cosymp: a spare's computation ahead: %s"


class Spares:
    """Sessions of the app's first view, built while the server is idle, before their page is asked
    for: a page asked for without settings (`/app`) gets one, so that its document is ready when its
    browser connects. Panel's warm `reuse_sessions` (app/warmup.py) builds a page's session while the
    browser loads the page's scripts, on the server's one thread: the page's 25 static files waited
    for the build (0.5-0.7 s), and the document for them (first plot 1.8-2.0 s after the request,
    1.35-1.45 s with a spare). A page with settings in its link gets its own session, built as
    before (what the link asks for is applied while it is built).

    One spare per app path, once a page without settings has been asked for there. The next is built
    after a page has loaded (`fill`, from the page's onload) and the server has then been idle
    IDLE_S: a build takes the server 0.35-0.6 s, which a change made meanwhile waits for. A spare is
    kept from the server's check for unused sessions until it is handed out, and then until its page
    has loaded (`loaded`) or HANDED_S have passed (its browser connects within a second or two; one
    that never does is then discarded as any page's session). While it waits, a spare builds its
    tabs' layouts in the server's idle time, and computes the results of its inputs the server
    remembers for every page (main.App._layouts_ahead)."""

    IDLE_S = 2.0
    HANDED_S = 60.0
    wanted: ClassVar[dict] = {}  # (application context, path) -> (request, application) to build a spare with
    ready: ClassVar[dict] = {}  # (application context, path) -> id of a built session
    building: ClassVar[set] = set()
    handed: ClassVar[dict] = {}  # id of a spare handed out -> the timer that lets it expire (unless its page loads first)
    _asking = contextvars.ContextVar("cosymp_spare_asking", default=None)
    _building = contextvars.ContextVar("cosymp_spare_building", default=False)

    @classmethod
    def serve(cls, get):
        """Panel's handler of a page's request: a page without settings may get a spare, and asks for
        one to be there for the next such page. A request counts as a change (Activity)."""

        @functools.wraps(get)
        async def handled(self, *args, **kwargs):
            Activity.touch()
            key = (self.application_context, self.request.path) if not self.request.query_arguments else None
            asking = cls._asking.set(key)
            try:
                await get(self, *args, **kwargs)
            finally:
                cls._asking.reset(asking)
            if key is not None:
                cls.wanted.setdefault(key, (self.request, self.application))

        handled.cosymp = True
        return handled

    @classmethod
    def session_id(cls, secret_key=None, signed=False):
        """The id Panel gives a page whose session it builds while the page loads: a spare's, when
        the page asked for none of the settings and a spare is ready (building it then finds it
        built)."""
        key = cls._asking.get()
        spare = cls.ready.pop(key, None) if key is not None else None
        session = key[0]._sessions.get(spare) if spare is not None else None
        if session is None:
            return generate_session_id(secret_key=secret_key, signed=signed)
        cls.handed[spare] = asyncio.get_running_loop().call_later(cls.HANDED_S, cls._unblock, spare, session)
        LOG.info(SPARE_HANDED, spare)
        return spare

    @classmethod
    def building_one(cls):
        """Whether the session being built now is a spare (then its page may be a while coming)."""
        return cls._building.get()

    @classmethod
    def loaded(cls, session):
        """A page has loaded in this session: if it was a spare, it no longer needs keeping."""
        timer = cls.handed.get(getattr(session, "id", None))
        if timer is not None:
            timer.cancel()
            cls._unblock(session.id, session)

    @classmethod
    def _unblock(cls, spare, session):
        del cls.handed[spare]
        session.unblock_expiration()

    @classmethod
    def fill(cls):
        """A page has loaded: build the spares that are wanted and missing, once the server is idle."""
        for key in set(cls.wanted) - set(cls.ready) - cls.building:
            cls.building.add(key)
            # In a context of its own: the loading page's (its curdoc) would reach the spare's callbacks.
            asyncio.get_running_loop().create_task(cls._build(key, *cls.wanted[key]), context=contextvars.Context())

    @classmethod
    async def _build(cls, key, request, app):
        context, _ = key
        try:
            while not Activity.idle(cls.IDLE_S):
                await asyncio.sleep(0.25)
            start = time.monotonic()
            spare = generate_session_id(secret_key=app.secret_key, signed=app.sign_sessions)
            token = generate_jwt_token(spare, secret_key=app.secret_key, signed=app.sign_sessions,
                                       expiration=app.session_token_expiration,
                                       extra_payload={"headers": {}, "cookies": {}, "arguments": {}})
            building = cls._building.set(True)
            try:
                session = await context.create_session_if_needed(spare, request, token)
            finally:
                cls._building.reset(building)
            session.block_expiration()
            cls.ready[key] = spare
            LOG.info(SPARE_BUILT, spare, time.monotonic() - start)
        finally:
            cls.building.discard(key)


def adjust_panel():
    """Panel's handling of the page's events, for this server process (once; each page runs main.py):
    a change is handled at once, not 50 ms later (Panel waits that long for more changes of the same
    widget to merge; each computation here merges the changes made while it runs), and what it
    causes reaches the page in one message. Pages load only the BokehJS bundles they use (and no
    polyfill of ES modules), no queued message waits for the next change to be sent, a page that
    closes while being written to leaves no traceback in the log, a page without settings gets a
    spare session, a page's stylesheet addresses are patched from its document's models, Panel
    makes a component's parameters writable for a moment without touching those that already are,
    a closed page's garbage is collected when the server is idle, Bokeh's properties compute their
    per-class constants once (app/properties.py), its messages map the document's models without a
    Python loop over them (app/messages.py) and a document's map of its models follows what changed
    without a walk of the page (app/graph.py)."""
    properties.install()
    messages.install()
    graph.install()
    Resources._default_components = BOKEH_BUNDLES
    # No polyfill of Panel's ESM components (es-module-shims) either: every page loaded it although
    # none of the app's components is one (tests/test_app_main.py checks); its script and what it did
    # took 27 ms of the page's main thread before the first plot (CPU profiles, mean of four loads).
    ReactiveESM.__javascript_raw__ = []
    Syncable._debounce = 0
    if not getattr(Syncable._change_event, "cosymp", False):
        Syncable._change_event = in_one_message(Syncable._change_event)
    # A closed page's full garbage collection, which Panel runs 5 s after destroying its document
    # whatever the server is then doing (134-294 ms in which no page was answered, found by the
    # loop's slow-callback log in the middle of a new page's load), asked of memory.Collector
    # instead, which runs it once the server is idle. A partial: Panel refuses to schedule a function
    # of the app's own modules (it takes them for the page's script, cleared with its session), and
    # a refusal there broke the closing session's destruction. One partial for the process: Panel
    # warns (twice in the log) when a page closes within 5 s of another unless it is given the same
    # callback it already scheduled.
    if getattr(document._garbage_collect, "func", None) != Collector.request:
        document._garbage_collect = functools.partial(Collector.request)
    if not getattr(document._dispatch_msgs, "cosymp", False):
        document._dispatch_msgs = no_stranded_messages(document._dispatch_msgs)
    if not getattr(WebSocketHandler.write_message, "cosymp", False):
        WebSocketHandler.write_message = closed_writes_seen(WebSocketHandler.write_message)
    if not getattr(server.patch_model_css, "cosymp", False):
        server.patch_model_css = sheets_from_the_document(server.patch_model_css)
    for name in EDITS_READONLY:
        importlib.import_module(name).edit_readonly = editable
    if not getattr(server.DocHandler.get, "cosymp", False):
        server.DocHandler.get = Spares.serve(server.DocHandler.get)
        server.generate_session_id = Spares.session_id


def serve_locally():
    """The current session's stylesheets from this server: Panel takes their address from the page's
    template variables, which a session built ahead of its page (Panel's warm `reuse_sessions`, set
    by app/warmup.py) never gets, and then linked them from Panel's CDN."""
    doc = pn.state.curdoc
    if doc is not None and doc.session_context is not None:
        doc._template_variables.setdefault("dist_url", f"{pn.state.rel_path}/{LOCAL_DIST}" if pn.state.rel_path
                                           else LOCAL_DIST)
