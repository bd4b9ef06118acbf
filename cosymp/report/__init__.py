"""Static HTML reports: one self-contained file that opens from disk with no network and no server.

A report is a document of sections holding text, figures (line plots of named series) and
tables; `render` writes it as one HTML file with everything inline: the data as JSON, the
plotting library (uPlot, MIT licence, vendored in `vendor/`, 51 kB) and the code that draws
the figures with zoom (drag a box; double-click resets), pan (shift-drag) and wheel zoom, and a
hover readout of every series at the cursor. Long series are reduced before they are embedded
(`envelope`): the minimum and maximum of each bin, so peaks survive.
"""
import html
import json
import math
import time
from dataclasses import dataclass, field
from importlib import resources

import numpy as np

from .. import series

MAX_POINTS = 4000


@dataclass
class Series:
    """One curve: label, x and y (NaN breaks the line), drawn dashed and/or with markers of a shape
    (style.FAMILY_MARKERS' names), with an opacity (alpha)."""

    label: str
    x: np.ndarray
    y: np.ndarray
    dash: bool = False
    points: bool = False
    color: str = None
    marker: str = "circle"
    alpha: float = 1.0


@dataclass
class Figure:
    """A plot of series against a shared x axis (series may have their own x values). A
    parametric figure (a phase portrait) draws each series in its own order instead. The series
    are drawn last to first, so that the first is on top (the first method over the second, as the
    app draws them); the legend lists them in order. With `zeros`, exact zeros on a log y axis are
    drawn at series.zero_floor (as in the app), and the caption says where; else they are left out
    (a structure-preserving method's exact zeros left its curve out of the figure the contrast is
    about)."""

    title: str
    xlabel: str
    ylabel: str
    series: list
    logx: bool = False
    logy: bool = False
    caption: str = ""
    parametric: bool = False
    zeros: bool = False


@dataclass
class Table:
    """A table: column headers and rows of cells (numbers are formatted, text escaped)."""

    columns: list
    rows: list
    caption: str = ""


@dataclass
class Section:
    """A heading, paragraphs of text and items (figures and tables) in order."""

    title: str
    text: list = field(default_factory=list)
    items: list = field(default_factory=list)


@dataclass
class Report:
    """A whole report: its title, an introduction, sections and the command that reproduces it."""

    title: str
    intro: list
    sections: list
    command: str = ""


PALETTE = ("#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
           "#7f7f7f", "#bcbd22", "#000000", "#393b79")


def envelope(x, y, max_points=MAX_POINTS):
    """series.envelope at the reports' resolution."""
    return series.envelope(x, y, max_points)


def thin(x, y, max_points=MAX_POINTS):
    """series.thin at the reports' resolution."""
    return series.thin(x, y, max_points)


def _array(values):
    v = np.asarray(values, float)
    text = np.char.mod("%.7g", v).astype(object)
    text[~np.isfinite(v)] = "null"
    return "[" + ",".join(text.tolist()) + "]"


def floor(fig):
    """Where the figure draws exact zeros (None: nowhere)."""
    if not (fig.zeros and fig.logy and any(np.any(np.asarray(s.y, float) == 0) for s in fig.series)):
        return None
    return series.zero_floor([s.y for s in fig.series])


def caption(fig, at):
    """The figure's caption, saying where its exact zeros are drawn (at, from `floor`)."""
    return fig.caption if at is None else f"{fig.caption} Exact zeros are drawn at {at:.0e}.".strip()


def _figure_json(fig, key, at):
    series = []
    for i, s in enumerate(fig.series):
        x, y = thin(s.x, s.y) if fig.parametric else envelope(s.x, s.y)
        if at is not None:
            y = np.where(y == 0, at, y)
        y = np.where(np.isfinite(y) & ((y > 0) | (not fig.logy)), y, np.nan)
        ok = np.isfinite(x) & ((x > 0) | (not fig.logx))
        x, y = x[ok], y[ok]
        order = np.arange(len(x)) if fig.parametric else np.argsort(x, kind="stable")
        style = json.dumps({"label": s.label, "dash": s.dash, "points": s.points, "marker": s.marker, "alpha": s.alpha,
                            "color": s.color or PALETTE[i % len(PALETTE)]}, ensure_ascii=False)
        series.append(f'{style[:-1]},"x":{_array(x[order])},"y":{_array(y[order])}}}')
    head = {"id": key, "title": fig.title, "xlabel": fig.xlabel, "ylabel": fig.ylabel, "logx": fig.logx,
            "logy": fig.logy, "parametric": fig.parametric}
    return json.dumps(head, ensure_ascii=False)[:-1] + ',"series":[' + ",".join(series) + "]}"


def _cell(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return f"<td>{html.escape(str(v))}</td>"
    text = f"{v:.3g}" if isinstance(v, float) and math.isfinite(v) else ("–" if isinstance(v, float) else str(v))
    return f'<td class="num">{text}</td>'




def _paragraphs(texts):
    return "".join(f"<p>{html.escape(t)}</p>" for t in texts)


def _asset(name):
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def log_axis_js():
    """The JavaScript of log axes' ticks and labels (`logTicks(lo, hi)`, `logLabel(tick, ticks)`),
    one rule for the report's axes and the app's."""
    return _asset("logaxis.js")


def render(report):
    """The report as one HTML document (a string)."""
    figures = []
    body = [f"<header><h1>{html.escape(report.title)}</h1>{_paragraphs(report.intro)}"]
    if report.command:
        body.append(f'<p class="command">Reproduce: <code>{html.escape(report.command)}</code></p>')
    body.append(f'<p class="meta">Generated by cosymp on {time.strftime("%Y-%m-%d %H:%M")}. Plots: drag a box '
                "to zoom, shift-drag to pan, wheel to zoom, double-click to reset; the legend reads the values "
                "at the cursor; click a legend entry to hide its curve.</p></header>")
    for sec in report.sections:
        body.append(f'<section><h2>{html.escape(sec.title)}</h2>{_paragraphs(sec.text)}')
        for item in sec.items:
            if isinstance(item, Figure):
                key, at = f"fig{len(figures)}", floor(item)
                figures.append(_figure_json(item, key, at))
                text = caption(item, at)
                cap = f"<figcaption>{html.escape(text)}</figcaption>" if text else ""
                body.append(f'<figure><div class="plot" id="{key}"></div>{cap}</figure>')
            else:
                head = "".join(f"<th>{html.escape(str(c))}</th>" for c in item.columns)
                rows = "".join("<tr>" + "".join(_cell(v) for v in r) + "</tr>" for r in item.rows)
                cap = f"<caption>{html.escape(item.caption)}</caption>" if item.caption else ""
                body.append(f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>")
        body.append("</section>")
    data = ("[" + ",".join(figures) + "]").replace("</", "<\\/")
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(report.title)}</title>"
            f"<style>{_asset('vendor/uPlot.min.css')}\n{_asset('report.css')}</style>"
            f"<script>{_asset('vendor/uPlot.iife.min.js')}</script></head><body>"
            + "".join(body)
            + f'<script id="figures" type="application/json">{data}</script>'
            f"<script>{log_axis_js()}\n{_asset('report.js')}</script></body></html>\n")


def write(report, path):
    """Render the report into `path`; returns its size in bytes."""
    text = render(report)
    with open(path, "w", encoding="utf-8") as f:
        f.write(text)
    return len(text.encode("utf-8"))
