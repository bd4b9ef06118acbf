"""A widget bound to a parameter of a page's state (a Job, which says what is wrong), and the
message an emptied number box gets."""
import param

from .jobs import Note
from .plotting import push


def empty(label):
    """What a number box that was emptied says (its value in use is put back)."""
    return Note("error", f"{label} is empty: type a number (the box shows the value in use again)")


def bound(cls, obj, name, **options):
    """A widget bound to obj's parameter `name` and always following it (a sidebar's)."""
    return ShownWidget(cls, obj, name, lambda: True, **options).widget


class ShownWidget:
    """A widget for the parameter `name` of `obj` that writes what the user sets into it at once but
    follows the parameter (its value, and its choices for a selector) only while `visible()`; one
    whose parameter changed meanwhile (`stale`) catches up when its tab is shown (`sync`). Made with
    `from_param`, a hidden tab's widgets followed every scene change: each change is a message to
    the page and a render there (BokehJS renders a MultiChoice anew, Choices.js, for each change of
    its options or value: 78 ms a scene change for Work–precision's two; the Stability map's eleven
    axis controls were 12% of the server's answer to a scene change). `from_param` also let an
    emptied number box write None into a parameter that takes numbers only (a ValueError in the
    server's log, nothing on the page)."""

    def __init__(self, cls, obj, name, visible, **options):
        self.obj, self.name, self.visible = obj, name, visible
        self.selector = isinstance(obj.param[name], param.Selector)
        # A bounded parameter's box gets no start and end: BokehJS put a value typed beyond them back
        # without a word (the map's 1000 cells became 30 again); the parameter refuses it, said (_write).
        self.widget = cls(**{"label": obj.param[name].label, **self._state(), **options})
        self._syncing = False
        self.stale = False  # the parameter changed while the tab was hidden
        self.widget.param.watch(self._write, "value")
        obj.param.watch(self._follow, name)
        if self.selector:
            obj.param.watch(self._follow, name, what="objects")

    def _state(self):
        value = getattr(self.obj, self.name)
        state = {"value": list(value) if isinstance(value, list) else value}
        if self.selector:
            p = self.obj.param[self.name]
            state["options"] = dict(p.names) if p.names else list(p.objects)  # shown by their labels
        return state

    def _write(self, event):
        if self._syncing:
            return
        if event.new is None:  # a number box emptied (BokehJS sends null): the value in use back, and why
            self.sync()
            self.obj.say(empty(self.widget.label))
            return
        try:
            setattr(self.obj, self.name, list(event.new) if isinstance(event.new, list) else event.new)
        except ValueError:  # beyond the parameter's bounds
            bounds = getattr(self.obj.param[self.name], "bounds", None)
            if bounds is None:
                raise
            self.sync()
            lo, hi = bounds
            self.obj.say(Note("error", f"{self.widget.label} = {event.new} is outside {lo}…{hi}: type a value "
                                       "within them (the box shows the value in use again)"))

    def _follow(self, *events):
        if self.visible():
            push(self.sync)
        else:
            self.stale = True

    def sync(self):
        """The widget set to the parameter's value and choices (a select the parameter's new choices
        leave without its value, set by the widget to the first one meanwhile, writes nothing back)."""
        self._syncing, self.stale = True, False
        try:
            self.widget.param.update(**self._state())
        finally:
            self._syncing = False
