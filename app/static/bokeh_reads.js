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
