// Camera interaction: the page computes eye/center/up itself from the state's camera (orbit about the
// centre, up kept orthogonal to the view direction) and sends at most one `camera` message per
// animation frame while a gesture lasts (interacting: true), then one with interacting: false.
"use strict";
window.VNR = window.VNR || {};

VNR.vec = {
  add: (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]],
  sub: (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]],
  scale: (a, s) => [a[0] * s, a[1] * s, a[2] * s],
  dot: (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2],
  cross: (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]],
  length: (a) => Math.hypot(a[0], a[1], a[2]),
  normalize(a) { const l = VNR.vec.length(a); return l > 0 ? VNR.vec.scale(a, 1 / l) : [0, 0, 0]; },
  // Rodrigues' rotation of v about the unit axis k by angle (radians).
  rotate(v, k, angle) {
    const V = VNR.vec, c = Math.cos(angle), s = Math.sin(angle);
    return V.add(V.add(V.scale(v, c), V.scale(V.cross(k, v), s)), V.scale(k, V.dot(k, v) * (1 - c)));
  },
};

// Pure camera operations on {eye, center, up, fovy}; each returns a new camera.
VNR.cameraOps = {
  copy: (c) => ({ eye: c.eye.slice(), center: c.center.slice(), up: c.up.slice(), fovy: c.fovy }),
  // Right and orthogonal up of a camera (unit vectors).
  basis(c) {
    const V = VNR.vec, forward = V.normalize(V.sub(c.center, c.eye));
    let right = V.normalize(V.cross(forward, c.up));
    if (V.length(right) === 0) right = V.normalize(V.cross(forward, Math.abs(forward[1]) < 0.9 ? [0, 1, 0] : [1, 0, 0]));
    return { forward, right, up: V.cross(right, forward) };
  },
  // yaw about the camera's up, then pitch about its right axis (radians); the centre stays put.
  orbit(c, yaw, pitch) {
    const V = VNR.vec, b = VNR.cameraOps.basis(c);
    let offset = V.rotate(V.sub(c.eye, c.center), b.up, yaw);
    const right = V.rotate(b.right, b.up, yaw);
    offset = V.rotate(offset, right, pitch);
    const up = V.rotate(b.up, right, pitch);
    const out = { eye: V.add(c.center, offset), center: c.center.slice(), up, fovy: c.fovy };
    out.up = VNR.cameraOps.basis(out).up;
    return out;
  },
  // Moves eye and centre in the view plane by (dx, dy) CSS pixels of a view `height` pixels tall.
  pan(c, dx, dy, height) {
    const V = VNR.vec, b = VNR.cameraOps.basis(c);
    const dist = V.length(V.sub(c.eye, c.center));
    const perPixel = dist * 2 * Math.tan((c.fovy * Math.PI) / 360) / Math.max(1, height);
    const move = V.add(V.scale(b.right, -dx * perPixel), V.scale(b.up, dy * perPixel));
    return { eye: V.add(c.eye, move), center: V.add(c.center, move), up: b.up, fovy: c.fovy };
  },
  // Scales the eye's distance to the centre by factor (< 1 moves closer), never closer than 0.1.
  zoom(c, factor) {
    const V = VNR.vec, offset = V.sub(c.eye, c.center), dist = V.length(offset);
    const next = Math.max(0.1, dist * factor);
    return { eye: V.add(c.center, V.scale(offset, next / dist)), center: c.center.slice(), up: c.up.slice(), fovy: c.fovy };
  },
};

// Pointer, wheel and touch gestures on the view canvases.
//   stateCamera(): the camera of the latest state; send(camera, interacting); viewHeight(): CSS px.
VNR.CameraController = class {
  constructor(elements, stateCamera, send, viewHeight) {
    this.stateCamera = stateCamera;
    this.sendCamera = send;
    this.viewHeight = viewHeight;
    this.camera = null;        // the local camera while a gesture lasts
    this.pointers = new Map(); // pointerId -> {x, y}
    this.mode = "orbit";
    this.frameRequest = 0;
    this.wheelTimer = 0;
    this.radiansPerPixel = 0.008;
    for (const el of elements) this.attach(el);
  }

  get interacting() { return this.camera !== null; }

  attach(el) {
    el.addEventListener("contextmenu", (e) => e.preventDefault());
    el.addEventListener("pointerdown", (e) => this.onDown(e, el));
    el.addEventListener("pointermove", (e) => this.onMove(e));
    el.addEventListener("pointerup", (e) => this.onUp(e, el));
    el.addEventListener("pointercancel", (e) => this.onUp(e, el));
    el.addEventListener("wheel", (e) => this.onWheel(e), { passive: false });
  }

  begin() {
    if (this.camera) return true;
    const c = this.stateCamera();
    if (!c) return false;
    this.camera = VNR.cameraOps.copy(c);
    return true;
  }

  onDown(e, el) {
    if (!this.begin()) return;
    e.preventDefault();
    try { el.setPointerCapture(e.pointerId); } catch { /* synthetic events (benchmarks) have no capture */ }
    el.classList.add("dragging");
    this.pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
    if (this.pointers.size === 1) this.mode = e.button === 2 || e.shiftKey ? "pan" : "orbit";
  }

  onMove(e) {
    const last = this.pointers.get(e.pointerId);
    if (!last || !this.camera) return;
    const ops = VNR.cameraOps;
    if (this.pointers.size === 1) {
      const dx = e.clientX - last.x, dy = e.clientY - last.y;
      if (this.mode === "pan") this.camera = ops.pan(this.camera, dx, dy, this.viewHeight());
      else this.camera = ops.orbit(this.camera, -dx * this.radiansPerPixel, -dy * this.radiansPerPixel);
      this.pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
    } else if (this.pointers.size === 2) {
      // Two fingers: the change of their distance zooms, the move of their midpoint pans.
      const [a, b] = [...this.pointers.values()];
      const before = { mid: [(a.x + b.x) / 2, (a.y + b.y) / 2], dist: Math.hypot(a.x - b.x, a.y - b.y) };
      this.pointers.set(e.pointerId, { x: e.clientX, y: e.clientY });
      const [c, d] = [...this.pointers.values()];
      const mid = [(c.x + d.x) / 2, (c.y + d.y) / 2], dist = Math.hypot(c.x - d.x, c.y - d.y);
      if (dist > 0 && before.dist > 0) this.camera = ops.zoom(this.camera, before.dist / dist);
      this.camera = ops.pan(this.camera, mid[0] - before.mid[0], mid[1] - before.mid[1], this.viewHeight());
    }
    this.schedule();
  }

  onUp(e, el) {
    if (!this.pointers.has(e.pointerId)) return;
    this.pointers.delete(e.pointerId);
    if (el.hasPointerCapture(e.pointerId)) el.releasePointerCapture(e.pointerId);
    if (this.pointers.size > 0) return;
    el.classList.remove("dragging");
    this.end();
  }

  onWheel(e) {
    e.preventDefault();
    if (this.pointers.size === 0 && !this.begin()) return;
    const pixels = e.deltaMode === 1 ? e.deltaY * 16 : e.deltaMode === 2 ? e.deltaY * 400 : e.deltaY;
    this.camera = VNR.cameraOps.zoom(this.camera, Math.exp(pixels * 0.0015));
    this.schedule();
    clearTimeout(this.wheelTimer);
    // The wheel has no "release": the gesture ends 150 ms after its last event.
    this.wheelTimer = setTimeout(() => { if (this.pointers.size === 0) this.end(); }, 150);
  }

  schedule() {
    if (this.frameRequest) return;
    this.frameRequest = requestAnimationFrame(() => {
      this.frameRequest = 0;
      if (this.camera) this.sendCamera(this.camera, true);
    });
  }

  end() {
    if (!this.camera) return;
    if (this.frameRequest) cancelAnimationFrame(this.frameRequest);
    this.frameRequest = 0;
    clearTimeout(this.wheelTimer);
    this.sendCamera(this.camera, false);
    this.camera = null;
  }
};
