/* Log axes' ticks and their labels, one rule for the app (Bokeh's CustomJSTicker and
   CustomJSTickFormatter run these) and the report (uPlot). */

/* The major ticks in [lo, hi] of a log axis: whole decades over 2 decades or more (every k-th, at
   most 9); under 2, 1, 2 and 5 times a power of ten (Bokeh's own ticker stepped linearly there, so
   1.1e-4 to 6.5e-3 had ticks at 0.001 ... 0.006 only, its lower decade none), or round linear steps
   where fewer than three of those fall inside (within a decade: at most six ticks; an axis narrower
   than about 1e-13 of its values, the Theta lesson's area ratio at 1 ± 1e-14, gets its two ends). */
function logTicks(lo, hi) {
  var a = Math.min(lo, hi), b = Math.max(lo, hi), out = [], k, i;
  if (!(a > 0) || !(b > a) || !isFinite(b)) return out;
  var la = Math.log10(a), lb = Math.log10(b), tol = 1e-9;
  if (lb - la >= 2) {
    var first = Math.ceil(la - tol), last = Math.floor(lb + tol), every = Math.max(1, Math.ceil((last - first) / 8));
    for (k = first; k <= last; k += every) out.push(parseFloat("1e" + k));
    return out;
  }
  for (k = Math.floor(la); k <= Math.ceil(lb); k++) {
    [1, 2, 5].forEach(function (m) {
      var v = parseFloat(m + "e" + k);
      if (v >= a * (1 - tol) && v <= b * (1 + tol)) out.push(v);
    });
  }
  if (out.length >= 3) return out;
  var raw = (b - a) / 5;
  if (!(raw > 0) || !isFinite(raw) || a / raw > 1e13) return [a, b];  // within a few ulps' steps: its ends
  var mag = Math.pow(10, Math.floor(Math.log10(raw))), step = 10 * mag;
  [1, 2, 5].forEach(function (m) { if (m * mag >= raw && m * mag < step) step = m * mag; });
  out = [];
  for (i = Math.ceil(a / step - tol); i * step <= b + tol * step; i++) {
    var v = parseFloat((i * step).toPrecision(15));
    if (v !== out[out.length - 1]) out.push(v);
  }
  return out;
}

/* A log-axis tick's label among the axis' ticks: 1e-5, 2e-17, 0.01, 100. An axis spanning less
   than a factor of 1.01 gets the digits that tell its ticks apart (1, 1.001, 1.002: three
   significant digits wrote 1, 1, 1 on a carried loop's area ratio). */
function logLabel(tick, ticks) {
  if (!(tick > 0)) return "";
  var pos = ticks.filter(function (v) { return v > 0; });
  var spread = pos.length > 1 ? pos[pos.length - 1] / pos[0] - 1 : 1;
  var digits = Math.min(15, Math.max(3, Math.ceil(-Math.log10(spread)) + 2));
  if (tick >= 1e-3 && tick < 1e5) return String(parseFloat(tick.toPrecision(digits)));
  var parts = tick.toExponential(digits - 1).split("e"), m = parts[0];
  if (m.indexOf(".") >= 0) m = m.replace(/0+$/, "").replace(/\.$/, "");
  return m + "e" + parts[1].replace("+", "");
}
