"""The page's plumbing: Panel and BokehJS adjusted so that a live page answers at once.

Each adjustment names what it saves; tests/test_app_main.py fails when a Panel or Bokeh release
changes what one relies on.
"""
import contextlib
import functools
from typing import ClassVar

import panel as pn
from bokeh.resources import Resources
from panel.io import document
from panel.io.document import unlocked
from panel.io.resources import LOCAL_DIST
from panel.io.state import set_curdoc
from panel.reactive import Syncable
from panel.theme import Bootstrap
from tornado.websocket import WebSocketClosedError, WebSocketHandler

REBOOT = "app/static/bootstrap_reboot.css"  # Bootstrap's Reboot section, verbatim (see Design)
# BokehJS adjusted in the page (served from app/static by the server; see each file).
SCRIPTS = {"cosymp_bokeh_reads": "app/static/bokeh_reads.js", "cosymp_bokeh_layouts": "app/static/bokeh_layouts.js"}


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
# 100 ms of its first load), which no figure or text of the app uses (the equations are KaTeX's;
# tests/test_app_main.py checks that no model of the page needs them). Panel's own bundle needs the
# tables bundle.
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


def adjust_panel():
    """Panel's handling of the page's events, for this server process (once; each page runs main.py):
    a change is handled at once, not 50 ms later (Panel waits that long for more changes of the same
    widget to merge; each computation here merges the changes made while it runs), and what it
    causes reaches the page in one message. Pages load only the BokehJS bundles they use, no
    queued message waits for the next change to be sent, and a page that closes while being
    written to leaves no traceback in the log."""
    Resources._default_components = BOKEH_BUNDLES
    Syncable._debounce = 0
    if not getattr(Syncable._change_event, "cosymp", False):
        Syncable._change_event = in_one_message(Syncable._change_event)
    if not getattr(document._dispatch_msgs, "cosymp", False):
        document._dispatch_msgs = no_stranded_messages(document._dispatch_msgs)
    if not getattr(WebSocketHandler.write_message, "cosymp", False):
        WebSocketHandler.write_message = closed_writes_seen(WebSocketHandler.write_message)


def serve_locally():
    """The current session's stylesheets from this server: Panel takes their address from the page's
    template variables, which a session built ahead of its page (Panel's warm `reuse_sessions`, set
    by app/warmup.py) never gets, and then linked them from Panel's CDN."""
    doc = pn.state.curdoc
    if doc is not None and doc.session_context is not None:
        doc._template_variables.setdefault("dist_url", f"{pn.state.rel_path}/{LOCAL_DIST}" if pn.state.rel_path
                                           else LOCAL_DIST)
