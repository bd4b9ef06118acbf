// One layout per message from the server in BokehJS 3.9, not one per changed property.
//
// A change of a layout property (visible, css_classes, a size, ...) of any component makes BokehJS
// lay out the whole page at once, synchronously, and each layout reads sizes back from the DOM, so
// the browser recomputes styles and layout too. A scene change brings a dozen such changes in one
// message (the scene's controls shown or hidden, the figures of another shape shown, the equations'
// panes): a dozen layouts of the whole page, about 130 ms. While a message is applied, a root
// asks for its layout once, after the last of its changes, still before anything is painted.
(function () {
  if (typeof Bokeh === "undefined" || typeof Bokeh.require !== "function") {
    return;
  }
  let layouts, documents;
  try {
    layouts = Bokeh.require("models/layouts/layout_dom");
    documents = Bokeh.require("document/document");
  } catch (err) {
    return;
  }
  const View = layouts && layouts.LayoutDOMView;
  const Doc = documents && documents.Document;
  const invalidate = View && View.prototype.invalidate_layout;
  const apply = Doc && Doc.prototype.apply_json_patch;
  if (typeof invalidate !== "function" || typeof apply !== "function") {
    return;
  }
  let applying = 0;
  const roots = new Set();
  View.prototype.invalidate_layout = function () {
    if (applying > 0 && !(this.parent instanceof View)) {
      roots.add(this);
      return;
    }
    invalidate.call(this);
  };
  Doc.prototype.apply_json_patch = function (...args) {
    applying += 1;
    try {
      return apply.apply(this, args);
    } finally {
      applying -= 1;
      if (applying === 0) {
        const waiting = [...roots];
        roots.clear();
        for (const root of waiting) {
          if (root.el.isConnected) {
            invalidate.call(root);
          }
        }
      }
    }
  };
  window.cosymp_bokeh_layouts = true;
})();
