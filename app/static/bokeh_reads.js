// Fewer style reads in BokehJS 3.9 (bokeh/bokeh#15286).
//
// BokehJS reads each visual property of every axis, grid, title and glyph (colour, width, dash,
// ...) through getComputedStyle on each paint, to honour --bk-* CSS variables, and a plot's font
// size the same way for every text it measures. A read after a DOM change makes the browser
// recompute styles, so a tab or a scene that builds figures paid for it once per read: half of the
// time it took to draw. cosymp sets no --bk-* variable (tests/test_app_main.py checks it), so
// its figures take their visuals from their models only, and a plot's font size is read once per
// task.
(function () {
  if (typeof Bokeh === "undefined" || typeof Bokeh.require !== "function") {
    return;
  }
  let visual, canvas;
  try {
    visual = Bokeh.require("core/visuals/visual");
    canvas = Bokeh.require("models/plots/plot_canvas");
  } catch (err) {
    return;
  }
  const props = visual && visual.VisualProperties && visual.VisualProperties.prototype;
  const plot = canvas && canvas.PlotView && canvas.PlotView.prototype;
  const font = plot && Object.getOwnPropertyDescriptor(plot, "base_font_size");
  if (!props || typeof props._get_css_value !== "function" || !font || typeof font.get !== "function") {
    return;
  }
  props._get_css_value = function () {
    return "";
  };
  Object.defineProperty(plot, "base_font_size", {
    configurable: true,
    get() {
      if (this._cosymp_font_size === undefined) {
        this._cosymp_font_size = font.get.call(this);
        queueMicrotask(() => {
          this._cosymp_font_size = undefined;
        });
      }
      return this._cosymp_font_size;
    },
  });
  window.cosymp_bokeh_reads = true;
})();

// Each element's size read once, together, while a root is built (the first page's roots).
//
// BokehJS builds a root's views depth first, and each element that is not a layout writes its style
// and at once reads its size back (`_after_render`: update_style, then update_bbox, through
// offsetParent and getBoundingClientRect): each read after the last element's write made the browser
// lay out the page again, a few hundred times for the first page. Here, while a root is built, an
// element writes its style and waits; the root's layout then reads the sizes of everything it lays
// out at once, and when the build is done the elements that waited read theirs in one pass, and
// those whose size changed are told so (`_after_resize`, as a resize observed later would: a
// toolbar's overflow, a tooltip's position, a canvas's size). First plot of a first page, 6 loads
// each, interleaved: 799 and 903 ms against 986 and 1112 ms (median).
(function () {
  if (typeof Bokeh === "undefined" || typeof Bokeh.require !== "function") {
    return;
  }
  let ui, dom, layouts;
  try {
    ui = Bokeh.require("models/ui/ui_element");
    dom = Bokeh.require("core/dom_view");
    layouts = Bokeh.require("models/layouts/layout_dom");
  } catch (err) {
    return;
  }
  const Element = ui && ui.UIElementView;
  const Layout = layouts && layouts.LayoutDOMView;
  const View = dom && dom.DOMView;
  if (!Element || !Layout || !View || typeof Element.prototype._after_render !== "function" ||
      typeof View.prototype.build !== "function" || typeof Element.prototype.update_bbox !== "function") {
    return;
  }
  const after_render = Element.prototype._after_render;
  const build = View.prototype.build;
  let building = 0;
  let waiting = [];
  Element.prototype._after_render = function () {
    if (building > 0 && !(this instanceof Layout)) {
      this.update_style();
      waiting.push(this);
      return;
    }
    return after_render.call(this);
  };
  View.prototype.build = function (target) {
    building += 1;
    try {
      return build.call(this, target);
    } finally {
      building -= 1;
      if (building === 0) {
        const views = waiting;
        waiting = [];
        const resized = views.filter((view) => view.el.isConnected && view.update_bbox());
        for (const view of resized) {
          view._after_resize();
        }
      }
    }
  };
  window.cosymp_bokeh_built = true;
})();
