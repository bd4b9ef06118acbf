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
     ranges below about 1e-16): ticks and labels as the app's (logaxis.js), readouts converted back. */
  function log10(arr) { return arr.map(function (v) { return v == null ? null : Math.log10(v); }); }

  function decades(u, axisIdx, min, max) {
    /* the log axis' ticks by the app's rule (logaxis.js), as log10 */
    var ticks = logTicks(Math.pow(10, min), Math.pow(10, max)).map(Math.log10);
    return ticks.length ? ticks : [min];
  }

  function steps(u, axisIdx, min, max) {
    /* 1-2-5 ticks at any magnitude (uPlot's own tables stop near 1e-16) */
    var span = max - min;
    if (!(span > 0)) return [min];
    var raw = span / 6, mag = Math.pow(10, Math.floor(Math.log10(raw))), step = 10 * mag;
    [1, 2, 5].forEach(function (m) { if (m * mag >= raw && m * mag < step) step = m * mag; });
    var out = [], first = Math.ceil(min / step);
    for (var i = 0; (first + i) * step <= max; i++) out.push((first + i) * step);
    return out;
  }

  /* Compact tick labels, as the app draws them: 4e-4, 1e5, 2500; ticks that differ only in late
     digits as offsets from the middle one (1, +2e-16), so no two labels read the same. */
  function trim(s) {
    var parts = s.split("e"), m = parts[0];
    if (m.indexOf(".") >= 0) m = m.replace(/0+$/, "").replace(/\.$/, "");
    return parts.length > 1 ? m + "e" + parts[1].replace("+", "") : m;
  }

  function places(step) {  /* the decimals that write every multiple of step exactly */
    for (var d = 0; d < 12; d++) {
      var x = step * Math.pow(10, d);
      if (Math.abs(x - Math.round(x)) < 1e-6 * x) return d;
    }
    return 12;
  }

  function compact(v, step, exp) {
    if (v === 0 || (step > 0 && Math.abs(v) < 1e-9 * step)) return "0";
    var a = Math.abs(v);
    if (!exp) return trim(v.toFixed(step > 0 ? places(step) : 3));
    var e = step > 0 ? Math.floor(Math.log10(step)) : 0;
    var mantissa = step > 0 ? Math.min(2, places(step / Math.pow(10, e))) : 2;
    var digits = step > 0 ? Math.max(1, Math.min(15, Math.floor(Math.log10(a)) - e + 1 + mantissa)) : 3;
    return trim(v.toExponential(digits - 1));
  }

  function ticks(vals) {
    var finite = vals.filter(function (v) { return v != null && isFinite(v); });
    if (!finite.length) return vals.map(function () { return ""; });
    var lo = Math.min.apply(null, finite), hi = Math.max.apply(null, finite), span = hi - lo;
    var big = Math.max(Math.abs(lo), Math.abs(hi)), step = finite.length > 1 ? span / (finite.length - 1) : 0;
    var ref = finite[Math.floor(finite.length / 2)], offset = span > 0 && span < 1e-4 * big;
    var nonzero = finite.map(Math.abs).filter(function (a) { return a > 1e-9 * step; });
    var exp = big >= 1e5 || (nonzero.length > 0 && Math.min.apply(null, nonzero) < 1e-3);  /* one form per axis */
    return vals.map(function (v) {
      if (v == null) return "";
      if (!offset) return compact(v, step, exp);
      if (v === ref) return trim(Math.abs(v) >= 1e5 || Math.abs(v) < 1e-3 ? v.toExponential(11) : v.toPrecision(12));
      var d = Math.abs(v - ref);
      return (v > ref ? "+" : "\u2212") + compact(d, step, d >= 1e5 || d < 1e-3);
    });
  }

  function axis(label, log, vertical) {
    var a = {label: label};
    if (log) {
      a.splits = decades;
      a.values = function (u, vals) {
        var ticks = vals.map(function (v) { return v == null ? null : Math.pow(10, v); });
        var drawn = ticks.filter(function (t) { return t != null; });
        return ticks.map(function (t) { return t == null ? "" : logLabel(t, drawn); });
      };
    } else {
      a.splits = steps;
      a.values = function (u, vals) { return ticks(vals); };
    }
    if (vertical) {
      /* wide enough for the longest tick label, plus the axis label */
      a.size = function (u, values) {
        var n = (values || []).reduce(function (m, v) { return Math.max(m, String(v).length); }, 3);
        return 34 + 7 * n;
      };
    }
    return a;
  }

  function padded(u, min, max) {
    /* linear ranges around the data's own size (uPlot's default falls back to 0..100 for tiny spans) */
    if (min == null || max == null) return [0, 1];
    var span = max - min, size = Math.max(Math.abs(min), Math.abs(max));
    var pad = span > 1e-12 * size ? 0.05 * span : (size > 0 ? 0.05 * size : 1);
    return [min - pad, max + pad];
  }

  function readout(log) {
    return function (u, v) { return fmt(v == null ? null : (log ? Math.pow(10, v) : v)); };
  }

  function polyline(u, sidx, i0, i1) {
    /* a parametric curve in its own order (uPlot's linear paths assume x sorted) */
    var xs = u.data[sidx][0], ys = u.data[sidx][1], p = new Path2D(), open = false;
    for (var i = i0; i <= i1; i++) {
      if (xs[i] == null || ys[i] == null) { open = false; continue; }
      var px = u.valToPos(xs[i], "x", true), py = u.valToPos(ys[i], "y", true);
      if (open) p.lineTo(px, py); else { p.moveTo(px, py); open = true; }
    }
    return {stroke: p, fill: null, clip: null, band: null, gaps: null, flags: 0};
  }

  /* Markers in the shape of the method's family (cosymp.report.style.FAMILY_MARKERS, Bokeh's
     names): [vertices, angle of the first in degrees, inner radius of a star] */
  var SHAPES = {triangle: [3, -90], inverted_triangle: [3, 90], diamond: [4, -90], square: [4, -45], hex: [6, 0],
                star: [5, -90, 0.45]};

  function marker(shape) {
    /* uPlot passes the x window's indices, which a parametric plot (mode 2, no shared x) does not
       have: there every point is drawn (uPlot drew none of the paper report's markers) */
    return function (u, sidx, i0, i1) {
      var pair = u.mode === 2, xs = pair ? u.data[sidx][0] : u.data[0], ys = pair ? u.data[sidx][1] : u.data[sidx];
      var r = 3.5 * (window.devicePixelRatio || 1), p = new Path2D(), poly = SHAPES[shape];
      var first = pair ? 0 : i0, last = pair ? xs.length - 1 : i1;
      for (var i = first; i <= last; i++) {
        if (xs[i] == null || ys[i] == null) continue;
        var x = u.valToPos(xs[i], "x", true), y = u.valToPos(ys[i], "y", true);
        if (shape === "plus") {
          p.moveTo(x - r, y); p.lineTo(x + r, y); p.moveTo(x, y - r); p.lineTo(x, y + r);
        } else if (shape === "x") {
          var d = r * Math.SQRT1_2;
          p.moveTo(x - d, y - d); p.lineTo(x + d, y + d); p.moveTo(x - d, y + d); p.lineTo(x + d, y - d);
        } else if (!poly) {
          p.moveTo(x + r, y); p.arc(x, y, r, 0, 2 * Math.PI);
        } else {
          var n = poly[0] * (poly[2] ? 2 : 1);
          for (var k = 0; k <= n; k++) {
            var a = (poly[1] + 360 * k / n) * Math.PI / 180, rk = poly[2] && k % 2 ? r * poly[2] : r * 1.2;
            if (k === 0) p.moveTo(x + rk * Math.cos(a), y + rk * Math.sin(a));
            else p.lineTo(x + rk * Math.cos(a), y + rk * Math.sin(a));
          }
        }
      }
      return {stroke: p, fill: shape === "plus" || shape === "x" ? null : p, clip: null, flags: 3};
    };
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

  /* uPlot draws its series in order, the last on top, and lists them in its legend in that order:
     the figure's series are given to it last to first, so that the first (the first method) is
     drawn over the others, and the legend's rows are put back in the figure's order. */
  function legendInOrder(u, n) {
    var rows = u.root.querySelectorAll(".u-legend .u-series");
    for (var k = n - 1; k >= 0; k--) rows[rows.length - 1].parentNode.appendChild(rows[rows.length - n + k]);
  }

  /* A live legend's values read the cursor's position: off the plot they would be empty boxes, so
     they (and the x readout's row) are shown only while the cursor is over the data. */
  function hovering(u) {
    u.root.classList.toggle("u-hovering", u.cursor.left != null && u.cursor.left >= 0);
  }

  var plots = window.cosympPlots = [];
  specs.forEach(function (spec) {
    var el = document.getElementById(spec.id);
    var drawn = spec.series.slice().reverse();
    var pairs = drawn.map(function (s) {
      return [spec.logx ? log10(s.x) : s.x, spec.logy ? log10(s.y) : s.y];
    });
    var data = spec.parametric ? [null].concat(pairs) : uPlot.join(pairs);
    var series = [spec.parametric ? {} : {label: spec.xlabel, value: readout(spec.logx)}];
    drawn.forEach(function (s) {
      var alpha = Math.round(255 * (s.alpha == null ? 1 : s.alpha)).toString(16).padStart(2, "0");
      var one = {
        label: s.label, stroke: s.color + alpha, width: 1.5, spanGaps: true, dash: s.dash ? [6, 4] : undefined,
        points: {show: s.points, size: 5, fill: s.color, paths: marker(s.marker)}, value: readout(spec.logy)
      };
      if (spec.parametric) {
        one.facets = [{scale: "x", auto: true}, {scale: "y", auto: true}];
        one.paths = polyline;
      }
      series.push(one);
    });
    var width = Math.max(320, Math.min(el.parentNode.clientWidth || 900, 1100));
    var plot = new uPlot({
      mode: spec.parametric ? 2 : 1, title: spec.title, width: width, height: 340, series: series, plugins: [panZoom()],
      scales: {x: {time: false}, y: {range: padded}},
      axes: [axis(spec.xlabel, spec.logx, false), axis(spec.ylabel, spec.logy, true)],
      cursor: {drag: {x: true, y: true, uni: 20}},
      legend: {live: !spec.parametric},
      hooks: {setCursor: [hovering]}
    }, data, el);
    legendInOrder(plot, drawn.length);
    plots.push(plot);
  });
  document.body.setAttribute("data-plots", String(specs.length));
})();
