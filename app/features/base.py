"""What a feature is, and the view every tab's view is built on."""
from dataclasses import dataclass, field

import panel as pn
import param

from cosymp.errors import InputError

from ..jobs import Job
from ..memory import MB
from ..plotting import push
from ..widgets import ShownWidget

AHEAD_BYTES = 16 * MB  # the largest lease a tab's computation takes ahead of its first showing (Follower.ahead)


@dataclass(frozen=True)
class Feature:
    name: str
    label: str
    view: object
    state: object = None
    url: dict = field(default_factory=dict)
    ahead: bool = True  # its tab is built ahead of its first showing, in the page's idle time


class FeatureView(pn.viewable.Viewer):
    """A tab's view: its layout (figures included) is built once, ahead of its first showing (in the
    page's idle time, hidden: `ahead`) or when it is first shown; new data then only replaces the
    figures' data. Data that arrives while another tab is shown is drawn when this one is shown
    again."""

    NAME = ""

    def __init__(self, study, state=None, **params):
        super().__init__(**params)
        self.study = study
        self.state = state
        self._layout = None
        self._stale = True
        self._opened = False
        self._widgets = []

    @property
    def visible(self):
        return self.study.view == self.NAME

    @property
    def built(self):
        return self._layout is not None

    def __panel__(self):
        if self._layout is None:
            self._layout = self.layout()
            self._stale = True
        return self._layout

    def wanted(self):
        """Called when the tab is shown, and when the study's scene changes while it is shown: a tab
        whose data is measured on demand starts a measurement here when it has none (its state drops
        the data of another scene), so that it never shows an empty tab or another scene's data."""

    def shown(self):
        """Its tab has become the shown one: a measurement starts if it has no data (`wanted`);
        data that changed meanwhile is drawn."""
        if not self._opened:
            self._opened = True
            self.study.param.watch(lambda event: self.visible and self.wanted(), ["scene"])
        self.wanted()
        if self._layout is not None and self._stale:
            self.redraw()
        stale = [w for w in self._widgets if w.stale]
        if stale:  # a sync of all eleven of the map's, none changed, took 4.7 ms of every visit
            push(lambda: [w.sync() for w in stale])

    def widget(self, cls, obj, name, **options):
        """A widget of class cls for obj's parameter `name`, following it while this tab is shown
        and brought up to date when it is shown again (ShownWidget)."""
        w = ShownWidget(cls, obj, name, lambda: self.visible, **options)
        self._widgets.append(w)
        return w.widget

    def ahead(self):
        """The steps (callables, each a short piece of the server's time) to take ahead of the tab's
        first showing, its layout built and hidden: compute its data where that is quick and small
        (`Follower.ahead`), and draw the data at hand, so that a first visit shows it at once."""
        return [*([self.state.ahead] if isinstance(self.state, Follower) else []), self._draw_stale]

    def _draw_stale(self):
        if self._stale:
            self.redraw()

    def follow(self, obj, *names):
        """Redraw when these parameters of obj change (now if shown, else when next shown)."""
        obj.param.watch(lambda *events: self.changed(), list(names))

    def changed(self):
        self._stale = True
        if self._layout is not None and self.visible:
            self.redraw()

    def redraw(self):
        self._stale = False
        push(self.update)

    def layout(self):
        raise NotImplementedError

    def update(self):
        raise NotImplementedError


class Follower(Job):
    """A computation derived from the sidebar's study, for one tab: recomputed when the study's
    WATCHED inputs change while its tab (NAME) is shown and it applies; its messages go to the
    study's."""

    study = param.Parameter(doc="The sidebar's study.")
    NAME = ""
    WATCHED = ()

    def __init__(self, study, **params):
        super().__init__(study=study, **params)
        study.param.watch(self._on_study, [*self.WATCHED, "view"])
        if self.active:
            self.refresh()

    @property
    def active(self):
        return self.study.view == self.NAME and self.applies()

    def applies(self):
        return True

    def ahead(self):
        """Compute now, for a tab not shown yet, if it applies, is expected to be quick and leases at
        most AHEAD_BYTES: every open page holds that lease while it shows its other tabs (a larger
        one is computed when the tab is shown, as before)."""
        if self.running or not self.applies() or not self.quick():
            return
        try:
            inputs = self._inputs()
        except InputError:
            return
        if inputs is not None and self._bytes(inputs) <= AHEAD_BYTES:
            self.refresh()

    def say(self, note):
        self.study.say(note)

    def _on_study(self, *events):
        if self.active:
            self.request()
