"""The served page (app/main.py) composed in-process, without a server or a browser."""
import panel as pn

from app import main
from app.state import VIEWS


def test_the_page_has_every_view_and_follows_the_study():
    app = main.App()
    page = app.template()
    assert isinstance(page, pn.template.BootstrapTemplate)
    assert len(app.tabs) == len(VIEWS)
    names = list(VIEWS.values())
    assert app.tabs.active == names.index(app.study.view)
    app.study.view = "structure"
    assert app.tabs.active == names.index("structure")
    app.tabs.active = names.index("long")
    assert app.study.view == "long"
    assert app.study.results is not None and all(e.comparison is not None for e in app.study.results.entries)
