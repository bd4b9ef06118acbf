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
      park(this);
      if (this._has_finished) {
        this.invalidate_layout();
      }
      return out;
    };
    // Panel's Tabs adds a rule to each tab's own style sheet at each layout, which that tab's own
    // layout clears first: a tab not shown is not laid out, and its sheet grew by a rule per layout
    // of the page for as long as the page lived (11 rules once the first page was built, 13 after
    // four scene changes). Its sheet is cleared here instead.
    const lay = tabs.prototype._update_layout;
    if (typeof lay === "function") {
      tabs.prototype._update_layout = function () {
        const laid = this.layoutable_views;
        for (const view of this.child_views) {
          if (!laid.includes(view)) {
            view.style.clear();
          }
        }
        return lay.call(this);
      };
    }
    const after = tabs.prototype._after_layout;
    if (typeof after === "function") {
      tabs.prototype._after_layout = function () {
        const out = after.call(this);
        park(this);
        return out;
      };
    }
  };
  // The contents of the tabs not shown are taken out of the document, each left a placeholder to
  // come back to. Panel hides them (visibility: hidden) in the document, so the browser kept their
  // ~800 shadow roots, and each style recalculation after a write to any shadow root's style sheet
  // collects the rules of every shadow root of the document: with the tabs built ahead, a write and
  // a read back took 1.5-2.6 ms against 0.74 without the hidden tabs, and a scene change makes
  // dozens of them. (The Tabs is then as tall as its shown tab; Panel's was as tall as its tallest.)
  const SPOT = "cosymp: a tab not shown";
  const park = (tabs) => {
    const { active } = tabs.model;
    const spots = new Set();
    tabs.child_views.forEach((view, i) => {
      const spot = view._cosymp_spot;
      const placed = view.el.parentNode === tabs.shadow_el;
      if (i === active) {
        view._cosymp_spot = undefined;
        if (placed || spot === undefined) {
          return;
        }
        if (spot.parentNode === tabs.shadow_el) {
          spot.replaceWith(view.el);
        } else {
          const header = tabs.header_el && tabs.header_el.parentNode === tabs.shadow_el ? tabs.header_el : null;
          tabs.shadow_el.insertBefore(view.el, header);
        }
        return;
      }
      if (placed) {
        const here = spot || document.createComment(SPOT);
        view.el.replaceWith(here);
        view._cosymp_spot = here;
      }
      if (view._cosymp_spot !== undefined) {
        spots.add(view._cosymp_spot);
      }
    });
    // The placeholders of tabs shown again after BokehJS put them back, or removed, go.
    for (const node of [...tabs.shadow_el.childNodes]) {
      if (node.nodeType === Node.COMMENT_NODE && node.data === SPOT && !spots.has(node)) {
        node.remove();
      }
    }
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

  // One write per style sheet and layout, and none when its text stays the same. A layout of the
  // page rewrites each laid-out element's own style sheets: it clears them and appends their rules
  // one by one, mostly back to the text they had. The browser counts a sheet rewritten to the same
  // text as changed, and each style recalculation after a change collects the rules of every shadow
  // root of the page again (see `park`). While the outermost layout writes (update_layout only
  // writes), a sheet's text is kept here; at its end the sheets whose text differs are written.
  // Eight scene changes asked for 2,011 writes: 419 were made.
  let dom;
  try {
    dom = Bokeh.require("core/dom");
  } catch (err) {
    dom = null;
  }
  const Sheet = dom && dom.InlineStyleSheet && dom.InlineStyleSheet.prototype;
  const text = Sheet && Object.getOwnPropertyDescriptor(Sheet, "css");
  const write = Sheet && Sheet._update;
  const update = View.prototype.update_layout;
  if (text && typeof text.get === "function" && typeof write === "function" && typeof update === "function") {
    let writing = 0;
    const kept = new Set();
    Object.defineProperty(Sheet, "css", {
      configurable: true,
      get() {
        return this._cosymp_css !== undefined ? this._cosymp_css : text.get.call(this);
      },
    });
    Sheet._update = function (css) {
      if (writing > 0) {
        this._cosymp_css = css;
        kept.add(this);
      } else if (text.get.call(this) !== css) {
        write.call(this, css);
      }
    };
    View.prototype.update_layout = function () {
      writing += 1;
      try {
        return update.call(this);
      } finally {
        writing -= 1;
        if (writing === 0) {
          for (const sheet of kept) {
            const css = sheet._cosymp_css;
            sheet._cosymp_css = undefined;
            if (text.get.call(sheet) !== css) {
              write.call(sheet, css);
            }
          }
          kept.clear();
        }
      }
    };
  }
  window.cosymp_bokeh_layouts = true;
})();
