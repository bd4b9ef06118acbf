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
    if (!tabbed) {
      shown_tab_only();
    }
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

  // A plot whose axes need more or less room lays out itself only. BokehJS lays out the whole page
  // for it (the plot asks its parent, up to the root), although a plot of fixed height that
  // stretches to its container's width keeps its size whatever its axes need: the page's layout,
  // 100 ms with the tabs built ahead, came with every change of a tick label's width.
  let canvas;
  try {
    canvas = Bokeh.require("models/plots/plot_canvas");
  } catch (err) {
    canvas = null;
  }
  const plot = canvas && canvas.PlotView && canvas.PlotView.prototype;
  const relayout = plot && plot._invalidate_layout_if_needed;
  if (typeof relayout === "function") {
    const local = function () {
      this.measure_layout();
      this.update_bbox();
      this._compute_layout();
      this.after_layout();
      this._layout_computed = true;
    };
    plot._invalidate_layout_if_needed = function () {
      const { height, width, sizing_mode } = this.model;
      const fixed = height != null && (sizing_mode == "stretch_width" || (sizing_mode == null && width != null));
      if (!fixed || !this.is_managed) {
        return relayout.call(this);
      }
      this.compute_layout = local;
      try {
        return relayout.call(this);
      } finally {
        delete this.compute_layout;
      }
    };
  }

  // Only what is shown is laid out: the visible components, and of a Tabs the shown tab. BokehJS
  // lays out every component, hidden ones too, and paints their plots: with the tabs and the other
  // scenes' figures built ahead, a layout of the page (a scene of another shape shown) laid out and
  // painted some 40 hidden plots, 400 ms. A component shown again asks for its layout then (BokehJS
  // does so when `visible` changes; a Tabs here when its shown tab changes). (Panel registers its
  // Tabs after this file runs: the first layout looks it up.)
  const views = Object.getOwnPropertyDescriptor(View.prototype, "layoutable_views");
  let TabsView = null;
  let tabbed = false;
  const shown_tab_only = () => {
    tabbed = true;
    const TabsModel = Bokeh.Models && Bokeh.Models.get("panel.models.tabs.Tabs");
    const tabs = TabsModel && TabsModel.prototype.default_view;
    const activate = tabs && tabs.prototype.update_active;
    if (typeof activate !== "function") {
      return;
    }
    TabsView = tabs;
    tabs.prototype.update_active = function () {
      const out = activate.call(this);
      if (this._has_finished) {
        this.invalidate_layout();
      }
      return out;
    };
  };
  // A component left out of the layout is not painted either, so it is not waited for: BokehJS
  // counts a view finished when all its children are, and a document idle (Panel's onload, its URL
  // updates) when its roots are.
  const base = Object.getPrototypeOf(View.prototype).has_finished;
  if (views && typeof views.get === "function" && typeof base === "function") {
    View.prototype.has_finished = function () {
      if (!base.call(this) || (this.is_layout_root && !this._layout_computed)) {
        return false;
      }
      const laid = new Set(this.layoutable_views);
      return this.child_views.every((view) => (view instanceof View && !laid.has(view)) || view.has_finished());
    };
    Object.defineProperty(View.prototype, "layoutable_views", {
      configurable: true,
      get() {
        const all = views.get.call(this).filter((view) => view.model.visible !== false);
        if (TabsView !== null && this instanceof TabsView) {
          const shown = this.child_views[this.model.active];
          return all.filter((view) => view === shown);
        }
        return all;
      },
    });
    // Nor does a component left out lay out the page when its size changes. Each component watches
    // its own size (a ResizeObserver), and one that resized laid out its root: after a scene of
    // another shape was shown, the hidden tabs' contents and the hidden figures resized, and each
    // laid out the page again (nine layouts of 25-45 ms in a row, after the one that counted).
    const resized = View.prototype._after_resize;
    const left_out = (view) => {
      for (let v = view; v.parent instanceof View; v = v.parent) {
        if (!v.parent.layoutable_views.includes(v)) {
          return true;
        }
      }
      return false;
    };
    View.prototype._after_resize = function () {
      if (!left_out(this)) {
        resized.call(this);
      }
    };
  }
  window.cosymp_bokeh_layouts = true;
})();
