// The view area: the latest image of each view drawn into the canvases of the layout (network |
// truth | side by side | split), the split divider, the slice strip, and the `viewport` messages
// that keep the server's image size equal to the area's device pixels (per half side by side).
//   #canvas-main: the one canvas of network / truth / split, the right (network) half side by side.
//   #canvas-truth: the left (truth) half side by side only.
"use strict";
window.VNR = window.VNR || {};

VNR.Views = class {
  constructor(send) {
    this.send = send;
    this.area = document.getElementById("views");
    this.main = document.getElementById("canvas-main");
    this.truthCanvas = document.getElementById("canvas-truth");
    this.divider = document.getElementById("split-divider");
    this.slices = document.getElementById("slices");
    this.sliceCanvases = {
      slice_truth: document.getElementById("slice-truth"),
      slice_network: document.getElementById("slice-network"),
      slice_difference: document.getElementById("slice-difference"),
    };
    this.images = {};          // view name -> ImageBitmap (newest decoded)
    this.view = { layout: "network", split: 0.5, slice: false };
    this.viewport = null;      // the state's {width, height}
    this.lastViewportSent = "";
    this.localSplit = null;    // while (and shortly after) dragging the divider
    this.localSplitUntil = 0;
    this.drawRequest = 0;
    this.drawTimes = [];       // for the displayed fps
    this.resizeTimer = 0;
    new ResizeObserver(() => {
      this.requestDraw();
      clearTimeout(this.resizeTimer);
      this.resizeTimer = setTimeout(() => this.sendViewport(false), 150);
    }).observe(this.area);
    this.attachDivider();
  }

  setState(state) {
    const layoutChanged = state.view.layout !== this.view.layout;
    const sliceChanged = state.view.slice !== this.view.slice;
    this.view = state.view;
    this.viewport = state.viewport;
    if (this.localSplit !== null && this.drag === undefined &&
        (Math.abs(this.localSplit - state.view.split) < 1e-4 || performance.now() > this.localSplitUntil)) {
      this.localSplit = null;
    }
    this.slices.hidden = !state.view.slice;
    if (layoutChanged || sliceChanged) {
      this.applyLayout();
      this.sendViewport(false);
    }
    this.requestDraw();
  }

  // Canvases visible and labelled for the layout.
  applyLayout() {
    const layout = this.view.layout, side = layout === "side_by_side";
    this.truthCanvas.hidden = !side;
    this.truthCanvas.style.left = "0";
    this.truthCanvas.style.width = "50%";
    this.main.style.left = side ? "50%" : "0";
    this.main.style.width = side ? "50%" : "100%";
    this.divider.hidden = layout !== "split";
    const both = side || layout === "split";
    document.getElementById("label-left").textContent = both ? "truth" : layout;
    document.getElementById("label-right").textContent = both ? "network" : "";
  }

  // The image size the server should render: the view area (or half of it) in device pixels.
  wantedViewport() {
    const dpr = window.devicePixelRatio || 1;
    const halves = this.view.layout === "side_by_side" ? 2 : 1;
    const clamp = (v) => Math.min(4096, Math.max(16, Math.round(v)));
    return { width: clamp((this.area.clientWidth / halves) * dpr), height: clamp(this.area.clientHeight * dpr) };
  }
  sendViewport(always) {
    const want = this.wantedViewport(), key = `${want.width}x${want.height}`;
    const current = this.viewport && `${this.viewport.width}x${this.viewport.height}`;
    if (!always && (key === current || key === this.lastViewportSent)) return;
    this.lastViewportSent = key;
    this.send({ type: "viewport", width: want.width, height: want.height });
  }

  onImage(view, bitmap) {
    const old = this.images[view];
    this.images[view] = bitmap;
    if (old && old.close) old.close();
    this.requestDraw();
  }
  clear() {
    for (const b of Object.values(this.images)) if (b && b.close) b.close();
    this.images = {};
    this.requestDraw();
  }

  requestDraw() {
    if (this.drawRequest) return;
    this.drawRequest = requestAnimationFrame(() => { this.drawRequest = 0; this.draw(); });
  }

  // Frames shown per second over the last second.
  fps() {
    const now = performance.now();
    while (this.drawTimes.length && this.drawTimes[0] < now - 1000) this.drawTimes.shift();
    return this.drawTimes.length;
  }

  draw() {
    const layout = this.view.layout, net = this.images.network, truth = this.images.truth;
    const mainCtx = this.prepare(this.main);
    if (layout === "side_by_side") {
      this.fit(this.prepare(this.truthCanvas), truth);
      this.fit(mainCtx, net);
    } else if (layout === "split") {
      this.drawSplit(mainCtx, truth, net);
    } else {
      this.fit(mainCtx, layout === "truth" ? truth || net : net || truth);
    }
    if (net || truth) this.drawTimes.push(performance.now());
    if (this.view.slice) {
      for (const [name, canvas] of Object.entries(this.sliceCanvases)) this.fit(this.prepare(canvas), this.images[name], false);
    }
  }

  // Sizes a canvas to its CSS box in device pixels, clears it, returns its context.
  prepare(canvas) {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    const ctx = canvas.getContext("2d");
    ctx.fillStyle = "#000";
    ctx.fillRect(0, 0, w, h);
    return ctx;
  }

  // Where an image of aspect iw/ih lands when fitted (contained) in the canvas.
  placement(ctx, iw, ih) {
    const cw = ctx.canvas.width, ch = ctx.canvas.height, s = Math.min(cw / iw, ch / ih);
    const w = iw * s, h = ih * s;
    return { x: (cw - w) / 2, y: (ch - h) / 2, w, h };
  }

  fit(ctx, bitmap, smooth = true) {
    if (!bitmap) return;
    // Coarse interaction frames are upscaled smoothly; slices keep their voxels (nearest).
    ctx.imageSmoothingEnabled = smooth;
    ctx.imageSmoothingQuality = "high";
    const p = this.placement(ctx, bitmap.width, bitmap.height);
    ctx.drawImage(bitmap, p.x, p.y, p.w, p.h);
  }

  splitValue() { return this.localSplit !== null ? this.localSplit : this.view.split; }

  // One canvas: truth left of the divider, network right of it.
  drawSplit(ctx, truth, net) {
    const ref = net || truth;
    const split = this.splitValue();
    this.divider.style.left = `${split * 100}%`;
    if (!ref) return;
    const p = this.placement(ctx, ref.width, ref.height);
    const cut = split * ctx.canvas.width;
    ctx.imageSmoothingEnabled = true;
    ctx.imageSmoothingQuality = "high";
    if (truth) ctx.drawImage(truth, p.x, p.y, p.w, p.h);
    if (net) {
      ctx.save();
      ctx.beginPath();
      ctx.rect(cut, 0, ctx.canvas.width - cut, ctx.canvas.height);
      ctx.clip();
      ctx.drawImage(net, p.x, p.y, p.w, p.h);
      ctx.restore();
    }
  }

  attachDivider() {
    const d = this.divider;
    let frame = 0;
    const flush = () => { frame = 0; this.send({ type: "view", split: this.localSplit }); };
    d.addEventListener("pointerdown", (e) => {
      e.preventDefault();
      d.setPointerCapture(e.pointerId);
      this.drag = e.pointerId;
      this.localSplit = this.view.split;
    });
    d.addEventListener("pointermove", (e) => {
      if (this.drag !== e.pointerId) return;
      const r = this.area.getBoundingClientRect();
      this.localSplit = Math.min(1, Math.max(0, (e.clientX - r.left) / Math.max(1, r.width)));
      this.requestDraw();
      if (!frame) frame = requestAnimationFrame(flush);
    });
    const up = (e) => {
      if (this.drag !== e.pointerId) return;
      this.drag = undefined;
      if (frame) cancelAnimationFrame(frame);
      flush();
      this.localSplitUntil = performance.now() + 1000;
    };
    d.addEventListener("pointerup", up);
    d.addEventListener("pointercancel", up);
  }
};
