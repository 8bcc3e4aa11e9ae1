// viser's once-a-second redraw rests while the page is still (console/web/resting_redraw.py).
//
// viser 1.1.1's client draws its 3D view on demand and, as a safety net for changes that never
// asked for a frame, once a second (`setInterval(() => invalidate(), RENDER_HEARTBEAT_MS)` in
// its App.tsx: the only interval its page starts). On a browser without a GPU each of those
// frames is drawn in software. This script runs before viser's bundle and wraps
// `window.setInterval`: an interval of 1000 ms whose callback is a bare call (`()=>f()`, the
// heartbeat as built) fires only while the page is busy -- within REST_AFTER_MS of the last
// server message that draws (anything but viser's GUI-only messages, the same rule by which its
// client draws after a message: messageQueue.ts), of the operator's input (pointer, wheel, key,
// touch: the camera) or of a resize or the tab being shown again. A message from viser's
// websocket worker in an unknown form counts as drawing. Every other interval is left alone.
// `window.__restingRedraw` counts what it did.
(() => {
  "use strict";
  const REST_AFTER_MS = 3000;
  const HEARTBEAT_MS = 1000;
  const BARE_CALL = /^\(\)\s*=>\s*[\w$]+\(\)$/;
  const state = { found: 0, drawn: 0, rested: 0, restAfterMs: REST_AFTER_MS };
  window.__restingRedraw = state;
  let busyAt = performance.now();
  const busy = () => { busyAt = performance.now(); };
  // viser's GUI-only messages (messageQueue.ts: typeSetGuiOnlyMessage and the Gui*Message
  // components; Gui3DMessage is a scene node): its client draws nothing for them.
  const GUI_ONLY = new Set(["SetGuiPanelLabelMessage", "NotificationShowMessage",
                            "NotificationUpdateMessage", "RemoveNotificationMessage"]);
  const guiOnly = (type) => typeof type === "string" &&
      ((type.startsWith("Gui") && type !== "Gui3DMessage") || GUI_ONLY.has(type));
  const onWorkerMessage = (event) => {
    const messages = event.data && event.data.messages;
    if (!Array.isArray(messages) || !messages.every((m) => m && guiOnly(m.type))) busy();
  };

  for (const kind of ["pointerdown", "pointermove", "wheel", "keydown", "touchstart", "resize"]) {
    window.addEventListener(kind, busy, { capture: true, passive: true });
  }
  document.addEventListener("visibilitychange", busy, { capture: true });

  const Worker0 = window.Worker;
  if (typeof Worker0 === "function") {
    const Worker = function (...args) {
      const worker = new Worker0(...args);
      worker.addEventListener("message", onWorkerMessage);
      return worker;
    };
    Worker.prototype = Worker0.prototype;
    window.Worker = Worker;
  }

  const setInterval0 = window.setInterval;
  window.setInterval = function (callback, ms, ...rest) {
    if (ms === HEARTBEAT_MS && typeof callback === "function" &&
        BARE_CALL.test(Function.prototype.toString.call(callback))) {
      state.found += 1;
      const beat = () => {
        if (performance.now() - busyAt > REST_AFTER_MS) {
          state.rested += 1;
          return;
        }
        state.drawn += 1;
        callback();
      };
      return setInterval0.call(this, beat, ms, ...rest);
    }
    return setInterval0.call(this, callback, ms, ...rest);
  };
})();
