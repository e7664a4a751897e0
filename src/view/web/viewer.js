// vnr view's page: the WebSocket connection (docs/VIEWER.md), frame decoding, the state that drives
// every control, error and connection banners, and window.vnrViewer for tests and benchmarks.
//
// Stable element ids (tests rely on them):
//   toolbar:   layout reset-camera screenshot description status-render-ms status-train-ms status-fps
//              status-accumulated status-refined
//   banners:   error error-text error-close conn-banner
//   views:     views canvas-main (network / truth / split; network half side by side) canvas-truth
//              (truth half side by side) split-divider slices slice-truth slice-network slice-difference
//   render:    render-mode render-strategy render-macrocells render-step render-shade light-azimuth
//              light-elevation render-density render-max-frames render-coarse-scale
//   TF:        tf-canvas tf-colorbar tf-colormap tf-max-opacity tf-range-lo tf-range-hi tf-range-lo-units
//              tf-range-hi-units tf-load tf-save scene-save
//   training:  train-panel train-start train-pause train-reset train-lr train-budget train-state train-step
//              train-loss train-psnr train-steps-per-second train-samples-per-second train-learning-rate
//              train-seconds loss-canvas save-name save-model save-status
//   slices:    slice-toggle slice-axis slice-position
//   time:      time-panel timestep timestep-value timestep-continuous timestep-switch-every
//   info:      info
"use strict";
window.VNR = window.VNR || {};

VNR.token = new URLSearchParams(location.search).get("token");
// Every request carries the token from the page's URL (the cookie works too when it is absent).
VNR.url = (path) => (VNR.token ? `${path}?token=${encodeURIComponent(VNR.token)}` : path);

VNR.Viewer = class {
  constructor() {
    this.ws = null;
    this.connected = false;
    this.info = null;
    this.state = null;
    this.errors = [];
    this.errorCount = null;      // the state's error_count already shown
    this.frames = {};            // view -> frames received
    this.lastHeader = {};        // view -> header of the newest frame
    this.decodeSeq = {};         // view -> sequence numbers, so a late decode never replaces a newer image
    this.shownSeq = {};
    this.versionAtSend = 0;      // the state version known when the page last sent a message
    this.reconnectDelay = 500;
    this.tracing = false;        // benchmarks: record timed events in trace
    this.trace = [];
    const send = (msg) => this.send(msg);
    this.tfEditor = new VNR.TfEditor(VNR.$("tf-canvas"), VNR.$("tf-colorbar"), (tf) => send({ type: "tf", ...tf }));
    this.panels = new VNR.Panels(send, this.tfEditor);
    this.views = new VNR.Views(send);
    this.camera = new VNR.CameraController(
      [VNR.$("canvas-main"), VNR.$("canvas-truth")],
      () => (this.state ? this.state.camera : null),
      (cam, interacting) => send({ type: "camera", eye: cam.eye, center: cam.center, up: cam.up, fovy: cam.fovy, interacting }),
      () => VNR.$("views").clientHeight);
    // The cursor over the network view (at most 10 messages a second): the brick cache decodes there first.
    const main = VNR.$("canvas-main");
    let cursorSent = 0;
    main.addEventListener("pointermove", (e) => {
      const now = performance.now();
      if (this.camera.interacting || now - cursorSent < 100) return;
      cursorSent = now;
      const r = main.getBoundingClientRect();
      const clamp = (v) => Math.min(1, Math.max(0, v));
      send({ type: "cursor", x: clamp((e.clientX - r.left) / r.width), y: clamp((e.clientY - r.top) / r.height) });
    });
    main.addEventListener("pointerleave", () => send({ type: "cursor" }));
    VNR.$("error-close").addEventListener("click", () => { VNR.$("error").hidden = true; });
    VNR.$("screenshot").href = VNR.url("/screenshot.png");
    VNR.$("tf-save").href = VNR.url("/tf.json");
    VNR.$("scene-save").href = VNR.url("/scene.json");
    setInterval(() => { VNR.$("status-fps").textContent = `${this.views.fps()}`; }, 500);
    this.connect();
  }

  connect() {
    const scheme = location.protocol === "https:" ? "wss:" : "ws:";
    const ws = new WebSocket(`${scheme}//${location.host}${VNR.url("/ws")}`);
    ws.binaryType = "arraybuffer";
    this.ws = ws;
    ws.onopen = () => {
      this.connected = true;
      this.reconnectDelay = 500;
      VNR.$("conn-banner").hidden = true;
    };
    ws.onmessage = (e) => {
      if (typeof e.data === "string") this.onText(e.data);
      else this.onFrame(e.data);
    };
    ws.onclose = () => {
      if (this.ws !== ws) return;
      this.connected = false;
      VNR.$("conn-banner").hidden = false;
      setTimeout(() => this.connect(), this.reconnectDelay);
      this.reconnectDelay = Math.min(5000, this.reconnectDelay * 2);
    };
  }

  // Raw send: an object is sent as JSON, a string as it is (tests send malformed text on purpose).
  send(msg) {
    if (!this.ws || this.ws.readyState !== WebSocket.OPEN) return false;
    this.versionAtSend = this.state ? this.state.version : 0;
    if (this.tracing) this.trace.push({ t: performance.now(), kind: "send", msg });
    this.ws.send(typeof msg === "string" ? msg : JSON.stringify(msg));
    return true;
  }

  onText(text) {
    let msg;
    try { msg = JSON.parse(text); } catch { return; }
    switch (msg.type) {
      case "hello":
        this.info = msg.info;
        this.errorCount = msg.state.error_count;
        this.panels.setInfo(msg.info);
        this.tfEditor.setHistogram(msg.histogram);
        this.applyState(msg.state);
        this.views.applyLayout();
        this.views.sendViewport(true);
        break;
      case "state": this.applyState(msg.state); break;
      case "losses": this.panels.onLosses(msg); break;
      case "error":
        this.showError(msg.message);
        this.panels.onSaveFailed();
        break;
      case "saved": this.panels.onSaved(msg); break;
      default: break; // pong and anything newer
    }
  }

  applyState(s) {
    this.state = s;
    if (this.tracing) this.trace.push({ t: performance.now(), kind: "state", version: s.version, camera: s.camera });
    if (this.errorCount !== null && s.error_count > this.errorCount && s.last_error) this.showError(s.last_error);
    this.errorCount = s.error_count;
    this.views.setState(s);
    this.panels.setState(s);
  }

  showError(message) {
    this.errors.push(message);
    VNR.$("error-text").textContent = message;
    VNR.$("error").hidden = false;
  }

  // uint32 LE header length, the JSON header, then the JPEG.
  onFrame(buffer) {
    const now = performance.now();
    if (buffer.byteLength < 4) return;
    const n = new DataView(buffer).getUint32(0, true);
    if (4 + n > buffer.byteLength) return;
    let header;
    try { header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, n))); } catch { return; }
    const view = header.view;
    this.frames[view] = (this.frames[view] || 0) + 1;
    this.lastHeader[view] = header;
    if (this.tracing) this.trace.push({ t: now, kind: "frame", header });
    this.updateStatus(header);
    const seq = (this.decodeSeq[view] = (this.decodeSeq[view] || 0) + 1);
    createImageBitmap(new Blob([new Uint8Array(buffer, 4 + n)], { type: "image/jpeg" }))
      .then((bitmap) => {
        if (seq < (this.shownSeq[view] || 0)) { bitmap.close(); return; }
        this.shownSeq[view] = seq;
        this.views.onImage(view, bitmap);
      })
      .catch(() => {});
  }

  updateStatus(h) {
    const main = this.lastHeader.network ? "network" : "truth";
    if (h.view !== main) return;
    VNR.$("status-render-ms").textContent = VNR.format(h.render_ms, 3);
    VNR.$("status-train-ms").textContent = VNR.format(h.train_ms, 3);
    VNR.$("status-accumulated").textContent = `${h.accumulated}`;
    VNR.$("status-refined").textContent = h.refined ? "refined" : "coarse";
    VNR.$("status-cache").textContent = h.cache
      ? ` · cache ${h.cache.bricks} bricks, ${h.cache.bricks ? Math.round(100 * (1 - h.cache.stale / h.cache.bricks)) : 100}% fresh` +
        (h.cache.pending ? `, ${h.cache.pending} to decode` : "")
      : "";
  }
};

const viewer = new VNR.Viewer();

// For tests and benchmarks: read-only views of the page's state plus a raw send.
window.vnrViewer = {
  get connected() { return viewer.connected; },
  get frames() { return viewer.frames; },
  get lastHeader() { return viewer.lastHeader; },
  get state() { return viewer.state; },
  get info() { return viewer.info; },
  get errors() { return viewer.errors; },
  get losses() { return viewer.panels.losses; },
  get psnr() { return viewer.panels.psnr; },
  send: (obj) => viewer.send(obj),
  // The state version the page knew when it last sent: a later state (version > this) reflects it.
  stateVersionSent: () => viewer.versionAtSend,
  // Timing hooks: set tracing = true, then read trace [{t (performance.now() ms), kind: send|state|frame, ...}].
  get tracing() { return viewer.tracing; },
  set tracing(on) { viewer.tracing = !!on; viewer.trace = []; },
  get trace() { return viewer.trace; },
};
