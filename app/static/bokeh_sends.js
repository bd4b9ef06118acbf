// At most one change from the page in flight to the server in BokehJS 3.9: changes made while the
// server handles the last one are sent together when it answers, a property's superseded values left
// out.
//
// BokehJS sends every change as a message of its own, and the server handles them one by one. A
// slider moved by the arrow keys sends two per press (its value and its throttled value): 20 quick
// presses were 40 messages, and the server was still reading them 90 ms after the last press, before
// it could compute the last value. Here the first change goes at once, as before; while the server
// has not answered it (its OK or ERROR reply), later changes wait and then go as one message, in
// their order, with only the last value of each property changed again meanwhile (not across another
// kind of event, such as a button's click, whose handler must see the values set before it). If no
// answer comes within WAIT_MS, what waits is sent anyway.
//
// Nor does the page send the bounds its auto ranges (DataRange1d) take from new data, or from a zoom:
// the server never reads them (every range follows the data in the page; a scene change resets it
// there), and each plot's update sent them back, a message or two the server handled and answered
// while the next change waited for the answer (20 arrow-key presses on θ, last press to settled:
// 108 / 129 -> 91 / 110 ms in two interleaved runs of benchmarks/latency.py).
(function () {
  if (typeof Bokeh === "undefined" || typeof Bokeh.require !== "function") {
    return;
  }
  let sessions, messages, kinds;
  try {
    sessions = Bokeh.require("client/session");
    messages = Bokeh.require("protocol/message");
    kinds = Bokeh.require("document/events");
  } catch (err) {
    return;
  }
  const Session = sessions && sessions.ClientSession;
  const Message = messages && messages.Message;
  const { DocumentEventBatch: Batch, ModelChangedEvent: Changed } = kinds || {};
  const proto = Session && Session.prototype;
  if (!proto || typeof proto._document_changed !== "function" || typeof proto._handle_ok !== "function" ||
      typeof proto._handle_error !== "function" || !Message || typeof Message.create !== "function" ||
      typeof Batch !== "function" || typeof Changed !== "function") {
    return;
  }
  const WAIT_MS = 1000;
  const handle_ok = proto._handle_ok;
  const handle_error = proto._handle_error;

  const bounds = (e) => e instanceof Changed && (e.attr === "start" || e.attr === "end") && e.model.type === "DataRange1d";
  const syncing = (event) => {  // as BokehJS's own _document_changed, less an auto range's bounds
    const events = event instanceof Batch ? (event.sync ? event.events : []) : [event];
    return events.filter((e) => e.sync && !bounds(e));
  };

  proto._send_now = function (events) {
    const patch = this.document.create_json_patch(events);
    const message = Message.create("PATCH-DOC", {}, patch);
    this._cosymp_flight = message.msgid();
    clearTimeout(this._cosymp_timer);
    this._cosymp_timer = setTimeout(() => this._cosymp_answered(this._cosymp_flight), WAIT_MS);
    this._connection.send(message);
  };

  proto._document_changed = function (event) {
    const events = syncing(event);
    if (events.length == 0) {
      return;
    }
    if (this._cosymp_flight == null) {
      this._send_now(events);
      return;
    }
    const queue = (this._cosymp_queue ??= []);
    const last = (this._cosymp_last ??= new Map());  // (model, attr) -> index in queue, since the last other event
    for (const e of events) {
      if (!(e instanceof Changed)) {
        last.clear();
        queue.push(e);
        continue;
      }
      const key = `${e.model.id}.${e.attr}`;
      const at = last.get(key);
      if (at !== undefined) {
        queue[at] = null;
      }
      last.set(key, queue.length);
      queue.push(e);
    }
  };

  proto._cosymp_answered = function (msgid) {
    if (msgid == null || msgid !== this._cosymp_flight) {
      return;
    }
    this._cosymp_flight = null;
    clearTimeout(this._cosymp_timer);
    const waiting = (this._cosymp_queue ?? []).filter((e) => e !== null);
    this._cosymp_queue = [];
    this._cosymp_last?.clear();
    if (waiting.length > 0) {
      this._send_now(waiting);
    }
  };

  proto._handle_ok = function (message) {
    this._cosymp_answered(message.reqid());
    return handle_ok.call(this, message);
  };
  proto._handle_error = function (message) {
    this._cosymp_answered(message.reqid());
    return handle_error.call(this, message);
  };
  window.cosymp_bokeh_sends = true;
})();
