"""The cosymp app: composition of the state objects and views into a page.

Serve it with `panel serve app` (or `panel serve app --setup app/warmup.py`, which loads every
compiled kernel before the first page). Everything is served from this server: the Bootstrap
template, KaTeX and BokehJS come from Panel's and Bokeh's bundled resources.
"""
import html
import io
from functools import partial
from pathlib import Path

import holoviews as hv
import panel as pn
import param

from cosymp.errors import InputError, RunError

from .allocator import map_large_blocks
from .presets import query_items
from .state import (
    LONG_URL_NAMES,
    URL_NAMES,
    VIEWS,
    GaugeStudy,
    LongHorizons,
    LongRun,
    Note,
    Playback,
    StabilityMap,
    Study,
    ThetaLesson,
    WorkPrecision,
    log_when_freed,
    study_report,
)
from .views import (
    CloudView,
    Controls,
    GaugeView,
    LongRunView,
    OrbitsView,
    PlayView,
    PresetLinks,
    SceneInfo,
    StabilityMapView,
    StructureView,
    ThetaView,
    WorkPrecisionView,
)
from .warmup import prepare

ASSETS = Path(__file__).resolve().parent.parent / "assets"
NOTIFY_MS = {"error": 10000, "warning": 10000, "info": 6000}


class App(param.Parameterized):
    """One session: the state objects (first computed from the link's settings), their views,
    URL sync and notifications."""

    def __init__(self, **params):
        super().__init__(**params)
        prepare(preload=False)
        query = pn.state.location.query_params if pn.state.location is not None else {}
        self._pending = []
        self._stopped = False
        map_large_blocks()
        log_when_freed(self)
        try:
            self.study = Study(**{k: query[u] for k, u in URL_NAMES.items() if u in query})
        except (ValueError, TypeError, InputError) as err:
            self._pending.append(Note("error", f"the link's settings could not be applied ({err}); "
                                               "showing the defaults"))
            self.study = Study()
        if self.study.message is not None:
            self._pending.append(self.study.message)
        self.gauges = GaugeStudy(study=self.study)
        self.lesson = ThetaLesson(study=self.study)
        self.playback = Playback()
        self.long = LongRun(study=self.study)
        self.measure = WorkPrecision(study=self.study)
        self.horizons = LongHorizons(study=self.study)
        self.stability = StabilityMap(study=self.study)
        self.study.param.watch(self._on_message, "message")
        s = self.study
        views = {"compare": partial(OrbitsView, study=s), "structure": partial(StructureView, study=s),
                 "cloud": partial(CloudView, study=s), "gauges": partial(GaugeView, gauges=self.gauges),
                 "theta": partial(ThetaView, lesson=self.lesson),
                 "play": partial(PlayView, study=s, playback=self.playback),
                 "long": partial(LongRunView, long=self.long),
                 "workprecision": partial(WorkPrecisionView, measure=self.measure, long=self.horizons),
                 "map": partial(StabilityMapView, stability=self.stability)}
        names = list(VIEWS.values())
        # Each tab is built when first shown (dynamic tabs render only the active one).
        self.tabs = pn.Tabs(*[(label, pn.param.ParamFunction(pn.bind(views[name]), lazy=True))
                              for label, name in VIEWS.items()],
                            active=names.index(s.view), dynamic=True, sizing_mode="stretch_width")
        self.tabs.param.watch(lambda e: setattr(self.study, "view", names[e.new]), "active")
        self.study.param.watch(lambda e: setattr(self.tabs, "active", names.index(e.new)), "view")
        if pn.state.location is not None:
            pn.state.location.sync(self.study, URL_NAMES, on_error=self._bad_url)
            pn.state.location.sync(self.long, LONG_URL_NAMES, on_error=self._bad_url)
        pn.state.onload(self._flush)
        pn.state.on_session_destroyed(self._stop)

    def _stop(self, session_context):
        """A closed page stops its background runs (the long run after its current chunk, the
        measurements before their next run) and gives back the memory of its results; nothing
        is drawn or notified for it any more."""
        self._stopped = True
        for background in (self.measure, self.horizons, self.stability):
            background.cancel()
        for derived in (self.long, self.study, self.gauges, self.lesson, self.stability):
            derived.release()

    def _on_message(self, event):
        if event.new is not None:
            self._notify(event.new.level, event.new.text)

    def _notify(self, level, text):
        if pn.state.notifications is not None and not self._stopped:
            getattr(pn.state.notifications, level)(text, duration=NOTIFY_MS[level])

    def _flush(self):
        """On load: write the whole state into the URL (so a copied link reopens it) and post the
        messages of the session's start."""
        if pn.state.location is not None:
            pn.state.location.update_query(
                **query_items({k: getattr(self.study, k) for k in URL_NAMES}, URL_NAMES),
                **query_items({k: getattr(self.long, k) for k in LONG_URL_NAMES}, LONG_URL_NAMES))
        for note in self._pending:
            self._notify(note.level, note.text)

    def _bad_url(self, values):
        self._notify("error", f"the link's settings {values} could not be applied: check the scene, method "
                              "and parameter names and values")

    def _report(self):
        """The report file of the current comparison; bad input becomes a message and a file saying so."""
        try:
            text = study_report(self.study)
        except (InputError, RunError) as err:
            self._notify("error", f"report: {err}")
            text = f"<!DOCTYPE html><html><body><p>No report: {html.escape(str(err))}</p></body></html>"
        return io.BytesIO(text.encode("utf-8"))

    def template(self):
        share = pn.widgets.Button(name="Copy link to this view", sizing_mode="stretch_width")
        share.js_on_click(code="navigator.clipboard.writeText(window.location.href);"
                               "cb_obj.label = 'Link copied';")
        busy = self.study.param.busy
        spinner = pn.indicators.LoadingSpinner(value=busy, visible=busy, size=24)
        download = pn.widgets.FileDownload(callback=self._report, filename="cosymp-report.html",
                                           label="Download report (HTML)", button_type="primary",
                                           sizing_mode="stretch_width")
        return pn.template.BootstrapTemplate(
            title="cosymp: structure-preserving integrators for time-dependent Hamiltonians",
            logo=str(ASSETS / "logo.svg"), favicon=str(ASSETS / "logo.svg"), header_background="#0b3d91",
            sidebar_width=360,
            sidebar=[Controls(study=self.study), pn.layout.Divider(), PresetLinks(), share, download],
            main=[pn.Row(SceneInfo(study=self.study), spinner, sizing_mode="stretch_width"), self.tabs],
        )


pn.extension("katex", notifications=True, design="bootstrap")
hv.extension("bokeh", logo=False)
App().template().servable(title="cosymp")
