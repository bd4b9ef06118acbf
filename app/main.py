"""The cosymp app: one page per browser session, composed from the registry of features.

Serve it with `panel serve app --setup app/warmup.py` (app/warmup.py makes the compiled kernels
ready first). Everything is served from this server: the Bootstrap template and BokehJS come from
Panel's and Bokeh's bundled resources, KaTeX's stylesheet and fonts from app/static (the equations
are typeset on the server: plotting.typeset).
"""
import asyncio
import contextlib
import html
import io
from pathlib import Path
from urllib.parse import parse_qsl, urlencode

import panel as pn
import param
from bokeh.models import CustomJS
from panel.io.state import set_curdoc

from cosymp.errors import InputError, RunError
from cosymp.methods import METHODS
from cosymp.scenes import SCENES

from . import memory
from .features import FEATURES
from .jobs import FAILURES, Job, Note, failure_text
from .memory import Collector, log_when_freed, map_large_blocks
from .page import LOG, SCRIPTS, SPARE_READY, SPARE_SAID, Activity, Design, Spares, adjust_panel, serve_locally
from .plotting import katex_fonts_css, push, rule
from .presets import URL_NAMES, parse_items, query_items
from .study import Controls, PresetLinks, SceneInfo, Study, rendered_report, report_inputs, waiting_text
from .warmup import prepare

ASSETS = Path(__file__).resolve().parent.parent / "assets"
NOTIFY_MS = {"error": 8000, "warning": 6000, "info": 4000}
# A comparison still running this long after it started says so in a notice (waiting_text) that stays
# until it ends: kapitza to T = 5000 took 21 s with the spinner its only sign.
WAITING_MS = 700
AHEAD_MS = 50  # from the page's answer (or a look at a busy server) to the next step built ahead (App._ahead)
AHEAD_WAIT_MS = 2000  # the next step after this long if the page has not said it is idle
# The page says it has drawn an ahead step when its main thread is next idle (after the step's
# models got their views): an odd `value` is a step sent, value + 1 the page's answer.
PACE_JS = """
const sent = cb_obj.value;
if (sent % 2 === 1)
  requestAnimationFrame(() => requestIdleCallback(() => { cb_obj.value = sent + 1 }, {timeout: 1000}));
"""
AHEAD_IDLE_S = 1.0  # after the last change in any page of the server
GONE_MS = 1000  # a page whose browser has gone this long stops (App._watch)
REPORT_POLL_S = 0.1  # how often the Download button's wait for the comparison looks and says its progress
REPORT_LABEL = "Download report (HTML)"
URL_MS = 250  # the URL follows a change of the shown state this long after (App._write_url)
DISCARDING = set()  # the tasks discarding closed pages' sessions (App._discard)
TOP_JS = "const main = document.getElementById('main'); if (main) main.scrollTop = 0;"  # the template's scrolled area
COPY_LINK_JS = """
const label = 'Copy link to this view';
const done = (text) => { source.label = text; setTimeout(() => { source.label = label; }, 2500); };
if (!(navigator.clipboard && window.isSecureContext)) {
  done('Copy failed: use the address bar');
} else {
  const waited = setTimeout(() => done('Not allowed to copy: use the address bar'), 1000);
  navigator.clipboard.writeText(window.location.href).then(
    () => { clearTimeout(waited); done('Link copied ✓'); },
    () => { clearTimeout(waited); done('Copy failed: use the address bar'); });
}
"""


class TopTabs(pn.Tabs):
    """Tabs that open a tab at its top: opened from a map cell far down the page, Orbits kept the
    map's scroll. The script is a Bokeh callback of the tabs' own model, not Panel's `jscallback`: a
    Panel link on the tabs made every change of their children (a tab built ahead, or joining the
    page at its first visit) walk each of the page's Bokeh models for links to make
    (panel.links.Callback._process_callbacks): 3.1 of the 4.7 s Panel spent updating layouts over
    eight page loads, each with a first visit (py-spy), 0.45 s with this."""

    def _get_model(self, doc, root=None, parent=None, comm=None):
        model = super()._get_model(doc, root, parent, comm)
        model.js_on_change("active", CustomJS(code=TOP_JS))
        return model


def no_report(why):
    """The file a report that could not be made is: a page saying why."""
    return f"<!DOCTYPE html><html><body><p>No report: {html.escape(str(why))}</p></body></html>"


class App(param.Parameterized):
    """One session: the study (first computed from the link's settings), each feature's state and
    view, the URL and the notifications."""

    def __init__(self, **params):
        super().__init__(**params)
        prepare(preload=False)
        map_large_blocks()
        log_when_freed(self)
        self._pending = []
        self._reporting = None  # the report being made (_report)
        self._stopped = False
        self._doc = pn.state.curdoc
        self._location = pn.state.location
        self._url_due = False
        # The raw query text (Panel's query_params turns numbers and JSON into values already).
        query = dict(parse_qsl(pn.state.location.search.lstrip("?"))) if pn.state.location is not None else {}
        known = set(URL_NAMES.values()) | {u for f in FEATURES for u in f.url.values()}
        unknown = sorted(set(query) - known)
        if unknown:  # a hand-edited link with a misspelt name showed another comparison, silently
            self._pending.append(Note("error", f"the link's {', '.join(unknown)} "
                                               f"{'is' if len(unknown) == 1 else 'are'} not a setting of this app "
                                               f"(settings: {', '.join(sorted(known))}): ignored"))
        self.study = self._study(query)
        self.states = {f.name: f.state(self.study) if f.state else None for f in FEATURES}
        for f in (f for f in FEATURES if f.url):
            values, bad = parse_items(query, f.url)
            try:
                self.states[f.name].param.update(**values)
            except (ValueError, TypeError) as err:
                bad.append(str(err))
            bad += [f"{f.url[k]}={v}" for k, v in values.items() if getattr(self.states[f.name], k) != v]  # refused
            if bad:
                self._pending.append(Note("error", f"the link's {', '.join(bad)} could not be applied: showing the "
                                                   "defaults"))
        self.views = {f.name: f.view(self.study, self.states[f.name]) for f in FEATURES}
        # Every computation of the page: the study's and the features' (a state is a Job or holds `jobs`).
        self.jobs = [self.study, self.study.late, self.study.carry, *(j for s in self.states.values()
                                   for j in ([s] if isinstance(s, Job) else getattr(s, "jobs", ())))]
        names = [f.name for f in FEATURES]
        self.tabs = TopTabs(*[(f.label, pn.Column(sizing_mode="stretch_width")) for f in FEATURES],
                            active=names.index(self.study.view), sizing_mode="stretch_width")
        self._show(self.study.view)
        self.tabs.param.watch(lambda e: setattr(self.study, "view", names[e.new]), "active")
        self.study.param.watch(self._on_view, "view")
        self.study.param.watch(self._on_message, "message")
        self.study.param.watch(self._on_running, "running")
        self._waiting = None  # the notice of a comparison that runs long
        if self.study.running and self._served():  # its first results in their thread: kernels compiling (Job.refresh)
            self._doc.add_timeout_callback(self._still_running, WAITING_MS)
        self.study.param.watch(lambda e: self._write_url(), "results")
        for f in FEATURES:
            if f.url:
                self.states[f.name].param.watch(lambda e: self._write_url(), list(f.url))
        self._ahead_done = set()
        self._ahead_pending = None  # a spare's jobs still to try, computing what the server remembers
        self._remembering = []  # the ones started (`_remember_ahead`), released when done or with the page
        self._ahead_steps = self._ahead_work()
        self.pace = pn.widgets.IntInput(value=0, visible=False)
        self._sent = -1  # the last step's odd number (`_ahead`)
        self.pace.jscallback(value=PACE_JS)
        self.pace.param.watch(self._paced, "value")
        self.study.param.watch(Activity.touch, [*Study.INPUTS, "view"])
        pn.state.onload(self._flush)
        pn.state.on_session_destroyed(self._stop)
        self._loaded = False
        if Spares.building_one():
            self._doc.add_timeout_callback(self._layouts_ahead, AHEAD_MS)

    def _study(self, query):
        """The study the link asks for; what cannot be applied is said, and the defaults stand in."""
        values, bad = parse_items(query, URL_NAMES)
        if values.get("view", "compare") not in {f.name for f in FEATURES}:
            bad.append(f"view={values.pop('view')}")
        for name, known in (("scene", SCENES), ("method", METHODS), ("other", METHODS)):
            if name in values and values[name] not in known:  # param's words named its own class
                bad.append(f"{URL_NAMES[name]}={values.pop(name)} (not one of {', '.join(known)})")
        try:
            study = Study(**values)
        except (ValueError, TypeError, InputError) as err:
            bad.append(str(err))
            study = Study()
        if bad:
            self._pending.append(Note("error", f"the link's settings {', '.join(bad)} could not be applied: showing "
                                               "the defaults"))
        if study.message is not None:
            self._pending.append(study.message)
        return study

    def _show(self, name):
        """Show a feature's tab: its view is built the first time, and drawn if its data changed."""
        box = self.tabs[[f.name for f in FEATURES].index(name)]
        view = self.views[name]
        if not len(box):
            box.append(view)
        view.shown()

    def _on_view(self, event):
        names = [f.name for f in FEATURES]
        if self.tabs.active != names.index(event.new):
            self.tabs.active = names.index(event.new)
        self._show(event.new)
        self._write_url()

    # What _stop calls, bound here: a session whose page never connected (a link fetched, not
    # opened) is destroyed after Bokeh has emptied this module's namespace (the page's script), and
    # _stop then failed on the name Collector (a warning in the log for each such session).
    _collect = Collector.request

    def _stop(self, session_context):
        """A closed page stops its background runs and gives back the memory of its results; nothing
        is drawn or notified for it any more. Reads nothing of this module's namespace (see _collect)."""
        if self._stopped:
            return
        self._stopped = True
        for state in [*self.states.values(), *self._remembering]:
            if state is not None:
                state.release()
        self.study.release()
        self._collect()

    def _on_running(self, event):
        """A comparison in its thread (a quick one runs in the change's handler) that is still running
        after WAITING_MS says what it computes in a notice, taken away when it ends."""
        if event.new and self._served():
            self._doc.add_timeout_callback(self._still_running, WAITING_MS)
        elif not event.new and self._waiting is not None:
            self._waiting.destroy()
            self._waiting = None

    def _still_running(self):
        text = waiting_text(self.study)
        if self.study.running and self._waiting is None and text and not self._stopped:
            with set_curdoc(self._doc):
                self._waiting = pn.state.notifications.info(html.escape(text), duration=0)

    def _on_message(self, event):
        if event.new is not None:
            self._notify(event.new.level, event.new.text)

    def _notify(self, level, text):
        """A toast. Its text is escaped: the toasts (notyf) set it as HTML, and messages quote what a
        link or a box held."""
        if pn.state.notifications is not None and not self._stopped:
            getattr(pn.state.notifications, level)(html.escape(text), duration=NOTIFY_MS[level])

    def _write_url(self):
        """The URL holds the state of the shown results (only ever a valid one), so a copied link
        reopens them. It is written URL_MS after a change, once for the changes made meanwhile: in
        the message that brought the results, the page's history.pushState made the browser
        recompute its styles in the middle of drawing them (7-20 ms of a scene change's, traced)."""
        if self._url_due:
            return
        if not self._served():
            self._url_now()
            return
        self._url_due = True
        self._doc.add_timeout_callback(self._url_now, URL_MS)

    def _url_now(self):
        self._url_due = False
        if self._location is None or self.study.results is None or self._stopped:
            return
        items = query_items(self.study.state(), URL_NAMES)
        for f in FEATURES:
            items.update(query_items({k: getattr(self.states[f.name], k) for k in f.url}, f.url))
        self._location.search = "?" + urlencode(items)

    def _flush(self):
        """On load (the browser has drawn the page): write the state into the URL and post the
        messages of the session's start, and start building the other tabs ahead. A page loading
        counts as a change: no page builds ahead from its request until a second after it is drawn
        (its document was fetched and drawn while closed pages built theirs: 2.1-3.7 s to the
        first plot over four page loads in a row, against 1.4 s for the first). The server's full
        garbage collections move to its idle time (memory.Collector)."""
        Activity.touch()
        self._loaded = True
        self._write_url()
        for note in self._pending:
            self._notify(note.level, note.text)
        self._next_ahead()
        if self._doc is not None and self._doc.session_context is not None:
            Spares.loaded(self._doc.session_context.session)
            Spares.fill()
            Collector.start(Activity.idle)
            self._gone = False
            self._watcher = self._doc.add_periodic_callback(self._watch, GONE_MS)

    def _watch(self):
        """Stop the page once its browser has been gone GONE_MS or more (seen gone twice in a row). Its
        session would be destroyed by the server's check for unused sessions, which stops it too, but
        not the first page's: Panel keeps that session for good, to write every later page's HTML
        from (Panel's reuse_sessions, app/warmup.py), and its long run or measurement went on after
        its page had closed. A closed page's session is then discarded (`_discard`)."""
        gone = self._closed()
        if gone and self._gone:
            self._doc.remove_periodic_callback(self._watcher)
            self._stop(None)
            self._discard()
        self._gone = gone

    def _discard(self):
        """Discard the session of a page that has gone, as the server's check for unused sessions
        would 15-32 s later (`panel serve`'s defaults), unless its expiration is blocked (the session
        Panel keeps to write pages from; a spare just handed out). Until then every full garbage
        collection of the server went through its objects: with a few closed pages lingering each
        took 160-350 ms, in which no page was answered. (Looked at after this callback: it holds
        the document's lock, which blocks expiration too.)"""
        context = self._doc.session_context
        session = getattr(context, "session", None)
        application = getattr(getattr(context, "server_context", None), "application_context", None)
        if session is None or application is None:
            return

        async def discard():
            if not (session.expiration_blocked or session.connection_count):
                await application._discard_session(session, lambda s: s.connection_count == 0)

        task = asyncio.ensure_future(discard())
        DISCARDING.add(task)  # the loop keeps only a weak reference to a task
        task.add_done_callback(DISCARDING.discard)

    def _ahead(self):
        """Build the tabs ahead of their first showing, hidden, while the server is idle (no change
        in any page for AHEAD_IDLE_S, nothing computing in this one): a first visit then shows it at
        once (it cost 0.5-1.8 s to build there, most of it the browser's), at the price of the
        server's idle time and the page's memory. One step at a time (`_ahead_work`), the next when
        the page has drawn it (`_paced`): a change that comes while one runs waits for that step only
        (a whole tab at once took the server 0.3-0.45 s, and a scene change made in the first seconds
        of a page waited 0.6 s). With Bokeh's properties memoized (app/properties.py) steps take
        10-90 ms of the server's time and 150-280 ms of the browser's, and every tab is built about
        6 s after the page is drawn."""
        if self._stopped or self._closed():
            return
        busy = any(j.running for j in self.jobs)
        if not busy and Activity.idle(AHEAD_IDLE_S):
            step = next(self._ahead_steps, None)
            if step is None:
                return
            self._sent += 2
            sent = self._sent
            push(lambda: (step(), self.pace.param.update(value=sent)))
            if self._served():
                self._doc.add_timeout_callback(lambda: self._sent == sent and self._next_ahead(), AHEAD_WAIT_MS)
            return
        self._next_ahead()

    def _layouts_ahead(self):
        """A spare session (page.Spares) builds its tabs' layouts while it waits for its page, one
        at a time in the server's idle time. A layout touches no document, so the page's first
        document stays as small, and its page's building ahead (`_ahead`, from its load on) only has
        its tabs join: their layouts took the server 40-130 ms each there, and a tab's first visit
        in the page's first seconds waited for the one under way, or built its own.

        It then computes, one at a time, the results of its inputs that the server remembers for
        every page where it remembers none yet (`_remember_ahead`), so once per server: a first
        visit of the Long run or the Stability map in a page's first second recalled nothing and
        computed, in a second message (Long run 0.6-0.9 s to its plots settled, recalled 0.4-0.5 s;
        Stability map 0.38-0.48, recalled 0.28)."""
        if self._stopped or self._loaded:
            return
        if Activity.idle(AHEAD_IDLE_S) and not any(j.running for j in self._remembering):
            view = next((self.views[f.name] for f in FEATURES if f.ahead and not self.views[f.name].built), None)
            with set_curdoc(self._doc):
                if view is not None:
                    view.__panel__()
                elif not self._remember_ahead():
                    LOG.info(SPARE_READY, self._doc.session_context.id)
                    return
        self._doc.add_timeout_callback(self._layouts_ahead, AHEAD_MS)

    def _remember_ahead(self):
        """Start the next computation whose result the server remembers for every page (Job.KEEP:
        the Long run's and the Stability map's, 0.1-0.2 s each here) of this page's inputs, where it
        remembers none yet and the memory is free; each is tried once. They run in jobs of their
        own, on a study of their own (the same inputs): nothing of the page's changes (its spinner
        follows its own jobs, its toasts its study's messages: its document is not touched while its
        page may be pulling it), and nothing of theirs stays on the page's study. What they would
        say goes to the server's log. Returns whether one started."""
        try:
            if self._ahead_pending is None:
                wanted = [type(s) for s in self.states.values() if isinstance(s, Job) and s.remembers_ahead()]
                self._ahead_pending = []
                if wanted:
                    study = Study(**{k: getattr(self.study, k) for k in Study.INPUTS})
                    study.release()  # it gives the jobs their inputs; its comparison's lease goes back now
                    study.param.watch(lambda e: e.new is not None and LOG.info(SPARE_SAID, e.new.text), "message")
                    self._ahead_pending = [cls(study) for cls in wanted]
            while self._ahead_pending:
                job = self._ahead_pending.pop(0)
                if job.remember_ahead():
                    self._remembering.append(job)
                    return True
        except FAILURES as err:  # said in the log; nothing more is computed ahead
            LOG.info(SPARE_SAID, failure_text(err))
            self._ahead_pending = []
        for job in self._remembering:
            job.release()
        self._remembering = []
        return False

    def _paced(self, event):
        """The page has drawn the last step built ahead and is idle: the next one AHEAD_MS later, a gap in
        which a change made on the page goes out at once (`_ahead`; with no gap the first scene change
        of a page took 589 and 836 ms in one run, with it 249 and 264). Steps
        went every AHEAD_MS regardless, and the browser took 150-280 ms to give each step's
        models their views: the messages queued in the page, and a change made in the first seconds
        waited behind them (the first scene change 470-520 ms against 160-230 later)."""
        if event.new == self._sent + 1:
            self._next_ahead()

    def _ahead_work(self):
        """The steps of building ahead, 10-90 ms each, per feature with `ahead`: its layout built,
        its layout joining the page (unless its tab was shown meanwhile), then its view's own steps
        (`FeatureView.ahead`: the data at hand drawn)."""
        for i, f in enumerate(FEATURES):
            if not f.ahead:
                continue
            view, box = self.views[f.name], self.tabs[i]
            self._ahead_done.add(f.name)
            if not view.built:  # a spare's may be (`_layouts_ahead`)
                yield view.__panel__
            yield lambda box=box, view=view: len(box) or box.append(view)
            yield from view.ahead()

    def _closed(self):
        """Whether the page's browser has gone (its session lingers until the server's next check
        for unused sessions, up to half a minute)."""
        context = self._doc.session_context if self._doc is not None else None
        session = getattr(context, "session", None)
        return session is not None and session.connection_count == 0

    def _served(self):
        return self._doc is not None and self._doc.session_context is not None  # no idle time otherwise

    def _next_ahead(self):
        if self._served():
            self._doc.add_timeout_callback(self._ahead, AHEAD_MS)

    async def _report(self):
        """The report file of the current comparison (`_report_text`); a click while one is being
        made gets that one (each click ran its own wait, and the last to end put back the first's
        'waiting' label for good)."""
        task = self._reporting
        if task is None:
            task = self._reporting = asyncio.ensure_future(self._report_text())
            task.add_done_callback(lambda _: setattr(self, "_reporting", None))
        return io.BytesIO((await task).encode("utf-8"))

    async def _report_text(self):
        """The report of the current comparison, once the comparison under way and the reference it
        awaits have come: the report takes their results. It computed them again, in the server's
        thread, where no page was answered meanwhile and the button said nothing (20 s for kapitza at
        T = 5000, in which the page's own comparison came). Meanwhile the button says what it waits
        for; settings changed meanwhile are the report's, and a message says so. Its inputs are read
        then, on the loop (`report_inputs`), and it is made in a thread, holding the memory of what
        it computes beyond the page's runs (`ReportInputs.bytes`). Bad input, or memory refused,
        becomes a message and a file saying so; a page closed meanwhile gets none made."""
        download, study = self._download, self.study
        clicked = {k: getattr(study, k) for k in Study.INPUTS}
        try:
            while not self._stopped and (study.running or study.late.running):
                job = study if study.running else study.late
                done = f" ({job.progress:.0%})" if job.progress > 0 else ""  # a comparison says none
                download.label = f"Report: waiting for {job.WHAT}{done}"
                await asyncio.sleep(REPORT_POLL_S)
            if self._stopped:
                return no_report("the page was closed")
            inputs = report_inputs(study)
            download.filename = inputs.filename
            if {k: getattr(study, k) for k in Study.INPUTS} != clicked:
                self._notify("info", "report: of the settings shown now, changed since Download was clicked")
            nbytes = inputs.bytes()
            lease = memory.BUDGET.lease(nbytes, "this report") if nbytes else None
            return await asyncio.get_running_loop().run_in_executor(None, rendered_report, inputs, lease)
        except (InputError, RunError) as err:
            self._notify("error", f"report: {err}")
            return no_report(err)
        finally:
            download.label = REPORT_LABEL

    def template(self):
        share = pn.widgets.Button(name="Copy link to this view", sizing_mode="stretch_width")
        share.js_on_click(code=COPY_LINK_JS)
        # Spins while any computation of the page runs (the comparison, a tab's lesson, study, run or
        # map): a tab still showing what it showed before a change says so. Shown and hidden by its style
        # only: a change of `visible` or of a component's classes makes BokehJS lay out the whole page
        # (Panel's own busy indicator, off below, did that on every event).
        spinner = pn.indicators.LoadingSpinner(value=True, size=24, styles=pn.bind(
            lambda *running: {"opacity": "1" if any(running) else "0"}, *(j.param.running for j in self.jobs)))
        download = self._download = pn.widgets.FileDownload(
            callback=self._report, filename="cosymp-report.html", label=REPORT_LABEL,
            button_type="primary", sizing_mode="stretch_width")
        return pn.template.BootstrapTemplate(
            title="cosymp: structure-preserving integrators for time-dependent Hamiltonians",
            logo=str(ASSETS / "logo.svg"), favicon=str(ASSETS / "logo.svg"), header_background="#0b3d91",
            sidebar_width=360, design=Design, busy_indicator=None,
            sidebar=[Controls(study=self.study), rule(), PresetLinks(), share, download, self.pace],
            main=[pn.Row(SceneInfo(study=self.study), spinner, sizing_mode="stretch_width"), self.tabs],
        )


adjust_panel()
serve_locally()
pn.extension(notifications=True, design=Design, js_files=SCRIPTS,
             global_css=[katex_fonts_css()])  # the page's head only: a shadow root's @font-face is ignored
# Bottom right: at the bottom left they covered the sidebar's boxes a message asks to change (a typed
# beta(t), x0 ...) and its Copy link and Download buttons; here they cover the lower corner of plots
# that an error leaves as they were.
pn.state.notifications.position = "bottom-right"
# One recomputation of the document's model graph (a walk of every model) when the page is built,
# not one per root the template adds (13, each over the graph so far): 0.12 s of the page's 0.37 s.
with pn.state.curdoc.models.freeze() if pn.state.curdoc is not None else contextlib.nullcontext():
    App().template().servable(title="cosymp")
