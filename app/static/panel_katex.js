// An equation's new text typeset in place, and each text typeset once per page (Panel 1.9's KaTeX pane).
//
// Panel's KaTeX view renders itself anew when its text changes: its shadow root emptied and every
// style sheet installed again (KaTeX's own among them), then the text typeset. A scene change
// changes three or four equations, and that took 10-20 ms of its main thread, most of it the style
// sheets. Here a view already rendered whose text changes gets the text's typeset HTML in its
// container only, from the page's cache when this text was typeset before (the scenes' equations
// come back with their scene). Any other render (the first, a style change) is Panel's own, and
// what it typeset is kept in the cache too.
(function () {
  if (typeof Bokeh === "undefined" || typeof Bokeh.require !== "function" || !Bokeh.Models) {
    return;
  }
  const delimiters = [
    { left: "$$", right: "$$", display: true },
    { left: "\\[", right: "\\]", display: true },
    { left: "$", right: "$", display: false },
    { left: "\\(", right: "\\)", display: false },
  ];
  const typeset = new Map();
  const KEEP = 64;
  const keep = (text, html) => {
    if (!typeset.has(text) && typeset.size >= KEEP) {
      typeset.delete(typeset.keys().next().value);
    }
    typeset.set(text, html);
  };
  let patched = false;
  const patch = () => {
    let model;
    try {
      model = Bokeh.Models.get("panel.models.katex.KaTeX");
    } catch (err) {
      return;
    }
    const view = model && model.prototype.default_view && model.prototype.default_view.prototype;
    const render = view && view.render;
    if (typeof render !== "function") {
      return;
    }
    patched = true;
    view.render = function () {
      const { text } = this.model;
      const shown = this._cosymp_text;
      if (shown === undefined || shown === text || this.container == null ||
          this.container.parentNode !== this.shadow_el || typeof window.renderMathInElement !== "function") {
        const out = render.call(this);
        this._cosymp_text = text;
        if (typeof window.renderMathInElement === "function" && this.container != null) {
          keep(text, this.container.innerHTML);
        }
        return out;
      }
      const html = typeset.get(text);
      if (html !== undefined) {
        this.container.innerHTML = html;
      } else {
        this.container.innerHTML = text;
        window.renderMathInElement(this.container, { delimiters });
        keep(text, this.container.innerHTML);
      }
      this._cosymp_text = text;
    };
    window.cosymp_panel_katex = true;
  };
  // Panel registers its models after this file runs (panel.min.js comes last).
  patch();
  let base;
  try {
    base = Bokeh.require("base");
  } catch (err) {
    return;
  }
  const register = base && base.register_models;
  if (patched || typeof register !== "function") {
    return;
  }
  base.register_models = function (...args) {
    const out = register.apply(this, args);
    if (!patched) {
      patch();
    }
    return out;
  };
})();
