// No console warnings for figures that have no data yet, in BokehJS 3.9.
//
// Every figure here is built once, before its data (a tab built ahead of its first showing is laid
// out hidden, with empty sources), and later only gets data. BokehJS warned at each layout of such a
// figure: "could not set initial ranges" (its range manager, which BokehJS's own internal plots keep
// quiet the same way) and, for a log axis, "could not determine minimum (and maximum) data value
// for log axis" (DataRange1d, which then takes 0.1 ... 10, as it does here without the warnings):
// 117 warnings in a visit of every tab, among which a real one would have been lost. A log axis
// whose data has no positive value but some other finite one still warns, as before.
(function () {
  if (typeof Bokeh === "undefined" || typeof Bokeh.require !== "function") {
    return;
  }
  let canvas, ranges;
  try {
    canvas = Bokeh.require("models/plots/plot_canvas");
    ranges = Bokeh.require("models/ranges/data_range1d");
  } catch (err) {
    return;
  }
  const plot = canvas && canvas.PlotView && canvas.PlotView.prototype;
  const range = ranges && ranges.DataRange1d && ranges.DataRange1d.prototype;
  if (!plot || typeof plot.initialize !== "function" || !range || typeof range._compute_range !== "function") {
    return;
  }
  const initialize = plot.initialize;
  plot.initialize = function (...args) {
    initialize.apply(this, args);
    if (this._range_manager) {
      this._range_manager.warn_initial_ranges = false;
    }
  };
  const compute = range._compute_range;
  const empty = (v) => !Number.isFinite(v);
  range._compute_range = function (min, max) {
    if (this.scale_hint == "log" && empty(min) && empty(max)) {
      return compute.call(this, 0.1, 10);
    }
    return compute.call(this, min, max);
  };
})();
