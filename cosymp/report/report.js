/* Draws the report's figures with uPlot: one plot per figure spec in #figures. */
(function () {
  "use strict";
  var specs = JSON.parse(document.getElementById("figures").textContent);

  function fmt(v) {
    if (v == null) return "–";
    var a = Math.abs(v);
    return (a !== 0 && (a < 1e-3 || a >= 1e5)) ? v.toExponential(3) : v.toPrecision(5);
  }

  /* Log axes are drawn as log10 of the data on a linear scale (uPlot's own log scale fails on
     ranges below about 1e-16): ticks at whole decades, readouts converted back. */
  function log10(arr) { return arr.map(function (v) { return v == null ? null : Math.log10(v); }); }

  function decades(u, axisIdx, min, max) {
    var lo = Math.ceil(min), hi = Math.floor(max), step = Math.max(1, Math.ceil((hi - lo) / 8)), out = [];
    for (var k = lo; k <= hi; k += step) out.push(k);
    return out.length ? out : [min, max];
  }

  function axis(label, log, size) {
    var a = {label: label, size: size};
    if (log) {
      a.splits = decades;
      a.values = function (u, vals) {
        return vals.map(function (v) { return v == null ? "" : (v === Math.round(v) ? "1e" + v : fmt(Math.pow(10, v))); });
      };
    } else {
      a.values = function (u, vals) {
        return vals.map(function (v) { return v == null ? "" : String(parseFloat(v.toPrecision(6))); });
      };
    }
    return a;
  }

  function readout(log) {
    return function (u, v) { return fmt(v == null ? null : (log ? Math.pow(10, v) : v)); };
  }

  function panZoom() {
    /* shift-drag pans, the wheel zooms around the cursor (pixel based) */
    return {hooks: {ready: function (u) {
      var over = u.over;
      function setRange(key, a, b) { u.setScale(key, {min: Math.min(a, b), max: Math.max(a, b)}); }
      over.addEventListener("mousedown", function (e) {
        if (!e.shiftKey) return;
        e.preventDefault(); e.stopPropagation();
        var x0 = e.clientX, y0 = e.clientY, w = over.clientWidth, h = over.clientHeight;
        var sx = [u.valToPos(u.scales.x.min, "x"), u.valToPos(u.scales.x.max, "x")];
        var sy = [u.valToPos(u.scales.y.min, "y"), u.valToPos(u.scales.y.max, "y")];
        function move(ev) {
          var dx = ev.clientX - x0, dy = ev.clientY - y0;
          setRange("x", u.posToVal(sx[0] - dx, "x"), u.posToVal(sx[1] - dx, "x"));
          setRange("y", u.posToVal(sy[0] - dy, "y"), u.posToVal(sy[1] - dy, "y"));
        }
        function up() { document.removeEventListener("mousemove", move); document.removeEventListener("mouseup", up); }
        document.addEventListener("mousemove", move);
        document.addEventListener("mouseup", up);
      }, true);
      over.addEventListener("wheel", function (e) {
        e.preventDefault();
        var f = e.deltaY < 0 ? 0.8 : 1.25, r = over.getBoundingClientRect();
        var left = e.clientX - r.left, top = e.clientY - r.top, w = over.clientWidth, h = over.clientHeight;
        setRange("x", u.posToVal(left - left * f, "x"), u.posToVal(left + (w - left) * f, "x"));
        setRange("y", u.posToVal(top - top * f, "y"), u.posToVal(top + (h - top) * f, "y"));
      }, {passive: false});
    }}};
  }

  var plots = window.cosympPlots = [];
  specs.forEach(function (spec) {
    var el = document.getElementById(spec.id);
    var pairs = spec.series.map(function (s) {
      return [spec.logx ? log10(s.x) : s.x, spec.logy ? log10(s.y) : s.y];
    });
    var data = spec.parametric ? [null].concat(pairs) : uPlot.join(pairs);
    var series = [spec.parametric ? {} : {label: spec.xlabel, value: readout(spec.logx)}];
    spec.series.forEach(function (s) {
      var one = {
        label: s.label, stroke: s.color, width: 1.5, spanGaps: true, dash: s.dash ? [6, 4] : undefined,
        points: {show: s.points, size: 5, fill: s.color}, value: readout(spec.logy)
      };
      if (spec.parametric) {
        one.facets = [{scale: "x", auto: true}, {scale: "y", auto: true}];
        one.paths = uPlot.paths.linear();
      }
      series.push(one);
    });
    var width = Math.max(320, Math.min(el.parentNode.clientWidth || 900, 1100));
    plots.push(new uPlot({
      mode: spec.parametric ? 2 : 1, title: spec.title, width: width, height: 340, series: series, plugins: [panZoom()],
      scales: {x: {time: false}},
      axes: [axis(spec.xlabel, spec.logx), axis(spec.ylabel, spec.logy, 70)],
      cursor: {drag: {x: true, y: true, uni: 20}},
      legend: {live: !spec.parametric}
    }, data, el));
  });
  document.body.setAttribute("data-plots", String(specs.length));
})();
