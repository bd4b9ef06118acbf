"""The served page (app/main.py) composed in-process, without a server or a browser."""
import panel as pn

from app import main
from app.features import FEATURES


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


def test_a_tab_is_built_when_first_shown_and_closing_the_page_releases_every_state():
    app = main.App()
    names = [f.name for f in FEATURES]
    shown = app.tabs[names.index("compare")]
    assert len(shown) == 1 and all(not len(app.tabs[i]) for i, n in enumerate(names) if n != "compare")
    app.study.view = "theta"
    assert len(app.tabs[names.index("theta")]) == 1 and app.states["theta"].results is not None
    app._stop(None)
    assert app.study._closed and all(s is None or getattr(s, "_closed", True) for s in app.states.values())
