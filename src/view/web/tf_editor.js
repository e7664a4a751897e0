// The transfer-function editor: the data's histogram (log counts) behind the opacity curve, whose
// control points are dragged (ends fixed at x = 0 and x = 1), added by double-click and removed by
// right-click or Delete; a colour bar of the colour map under it. x runs across the TF window
// [range lo, range hi] of normalised values; y is opacity per voxel step in [0, max opacity].
"use strict";
window.VNR = window.VNR || {};

VNR.TfEditor = class {
  constructor(canvas, colorbar, send) {
    this.canvas = canvas;
    this.colorbar = colorbar;
    this.send = send;          // send({opacity: [[x, a], ...]})
    this.tf = null;            // the state's tf
    this.histogram = [];
    this.colorStops = [];      // [[position in the window 0..1, r, g, b]] for the colour bar
    this.maxOpacity = 1;
    this.local = null;         // points being edited, shown until the state reflects them
    this.localUntil = 0;
    this.dragIndex = -1;
    this.selected = -1;
    this.frameRequest = 0;
    this.pad = 6;
    canvas.tabIndex = 0;
    canvas.addEventListener("pointerdown", (e) => this.onDown(e));
    canvas.addEventListener("pointermove", (e) => this.onMove(e));
    canvas.addEventListener("pointerup", (e) => this.onUp(e));
    canvas.addEventListener("pointercancel", (e) => this.onUp(e));
    canvas.addEventListener("dblclick", (e) => this.onDoubleClick(e));
    canvas.addEventListener("contextmenu", (e) => this.onContextMenu(e));
    canvas.addEventListener("keydown", (e) => this.onKey(e));
    new ResizeObserver(() => this.draw()).observe(canvas);
  }

  points() { return this.local || (this.tf ? this.tf.opacity : []); }

  // The edited points stay on screen until the state shows them (or for a second: a refused edit).
  setState(tf) {
    this.tf = tf;
    if (this.local && this.dragIndex < 0 &&
        (VNR.TfEditor.samePoints(tf.opacity, this.local) || performance.now() > this.localUntil)) {
      this.local = null;
    }
    this.draw();
  }
  static samePoints(a, b) {
    return a.length === b.length && a.every((p, i) => Math.abs(p[0] - b[i][0]) < 1e-4 && Math.abs(p[1] - b[i][1]) < 1e-4);
  }
  setHistogram(counts) { this.histogram = counts || []; this.draw(); }
  setColorStops(stops) { this.colorStops = stops; this.drawColorbar(); }
  setMaxOpacity(v) { if (v > 0) { this.maxOpacity = v; this.draw(); } }

  // Canvas pixel <-> (x, opacity).
  size() {
    const dpr = window.devicePixelRatio || 1, c = this.canvas;
    const w = Math.max(1, Math.round(c.clientWidth * dpr)), h = Math.max(1, Math.round(c.clientHeight * dpr));
    if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
    return { w, h, dpr };
  }
  toCanvas(p) {
    const { w, h, dpr } = this.size(), pad = this.pad * dpr;
    return [pad + p[0] * (w - 2 * pad), h - pad - (p[1] / this.maxOpacity) * (h - 2 * pad)];
  }
  fromEvent(e) {
    const r = this.canvas.getBoundingClientRect(), pad = this.pad;
    const x = (e.clientX - r.left - pad) / Math.max(1, r.width - 2 * pad);
    const y = (r.bottom - pad - e.clientY) / Math.max(1, r.height - 2 * pad);
    return [Math.min(1, Math.max(0, x)), Math.min(this.maxOpacity, Math.max(0, y * this.maxOpacity))];
  }
  hit(e) {
    const r = this.canvas.getBoundingClientRect(), dpr = this.size().dpr, pts = this.points();
    let best = -1, bestDist = 9;
    pts.forEach((p, i) => {
      const [cx, cy] = this.toCanvas(p);
      const d = Math.hypot(cx / dpr - (e.clientX - r.left), cy / dpr - (e.clientY - r.top));
      if (d < bestDist) { best = i; bestDist = d; }
    });
    return best;
  }

  onDown(e) {
    if (e.button !== 0) return;
    const i = this.hit(e);
    this.selected = i;
    if (i < 0) { this.draw(); return; }
    this.canvas.setPointerCapture(e.pointerId);
    this.local = this.points().map((p) => p.slice());
    this.dragIndex = i;
    this.draw();
  }
  onMove(e) {
    if (this.dragIndex < 0) return;
    const pts = this.local, i = this.dragIndex, [x, y] = this.fromEvent(e);
    const last = pts.length - 1;
    // The ends stay at x = 0 and x = 1; inner points stay between their neighbours.
    pts[i][0] = i === 0 ? 0 : i === last ? 1 : Math.min(pts[i + 1][0], Math.max(pts[i - 1][0], x));
    pts[i][1] = y;
    this.draw();
    if (!this.frameRequest) {
      this.frameRequest = requestAnimationFrame(() => { this.frameRequest = 0; this.commit(); });
    }
  }
  onUp(e) {
    if (this.dragIndex < 0) return;
    if (this.canvas.hasPointerCapture(e.pointerId)) this.canvas.releasePointerCapture(e.pointerId);
    if (this.frameRequest) cancelAnimationFrame(this.frameRequest);
    this.frameRequest = 0;
    this.dragIndex = -1;
    this.commit();
  }
  onDoubleClick(e) {
    if (this.hit(e) >= 0) return;
    const p = this.fromEvent(e);
    const pts = this.points().map((q) => q.slice());
    if (p[0] <= 0 || p[0] >= 1) return;
    pts.push(p);
    pts.sort((a, b) => a[0] - b[0]);
    this.local = pts;
    this.selected = pts.indexOf(p);
    this.commit();
  }
  onContextMenu(e) {
    e.preventDefault();
    this.remove(this.hit(e));
  }
  onKey(e) {
    if ((e.key === "Delete" || e.key === "Backspace") && this.selected >= 0) {
      e.preventDefault();
      this.remove(this.selected);
    }
  }
  remove(i) {
    const pts = this.points();
    if (i <= 0 || i >= pts.length - 1) return; // the ends cannot go
    this.local = pts.filter((_, j) => j !== i).map((q) => q.slice());
    this.selected = -1;
    this.commit();
  }
  commit() {
    if (!this.local) return;
    this.localUntil = performance.now() + 1000;
    clearTimeout(this.revertTimer);
    this.revertTimer = setTimeout(() => { if (this.tf) this.setState(this.tf); }, 1100);
    this.send({ opacity: this.local.map((p) => [p[0], p[1]]) });
    this.draw();
  }

  draw() {
    const c = this.canvas, ctx = c.getContext("2d"), { w, h, dpr } = this.size();
    ctx.clearRect(0, 0, w, h);
    this.drawHistogram(ctx, w, h, dpr);
    const pts = this.points();
    if (!pts.length) return;
    ctx.strokeStyle = "#e8e8e8";
    ctx.lineWidth = 1.5 * dpr;
    ctx.beginPath();
    pts.forEach((p, i) => { const [x, y] = this.toCanvas(p); if (i) ctx.lineTo(x, y); else ctx.moveTo(x, y); });
    ctx.stroke();
    pts.forEach((p, i) => {
      const [x, y] = this.toCanvas(p);
      ctx.fillStyle = i === this.selected ? "#4c9be8" : "#ffffff";
      ctx.beginPath();
      ctx.arc(x, y, 4 * dpr, 0, 2 * Math.PI);
      ctx.fill();
    });
  }

  // Log counts of the normalised values, placed across the TF window.
  drawHistogram(ctx, w, h, dpr) {
    const bins = this.histogram, n = bins.length;
    if (!n || !this.tf) return;
    const [lo, hi] = this.tf.range, span = Math.max(1e-9, hi - lo), pad = this.pad * dpr;
    const top = Math.max(...bins.map((b) => Math.log1p(b))) || 1;
    ctx.fillStyle = "rgba(120, 140, 170, 0.45)";
    for (let b = 0; b < n; ++b) {
      const x0 = pad + ((b / n - lo) / span) * (w - 2 * pad), x1 = pad + (((b + 1) / n - lo) / span) * (w - 2 * pad);
      if (x1 < 0 || x0 > w) continue;
      const bh = (Math.log1p(bins[b]) / top) * (h - 2 * pad);
      ctx.fillRect(x0, h - pad - bh, Math.max(1, x1 - x0), bh);
    }
  }

  drawColorbar() {
    const c = this.colorbar, dpr = window.devicePixelRatio || 1;
    c.width = Math.max(1, Math.round(c.clientWidth * dpr));
    c.height = Math.max(1, Math.round(c.clientHeight * dpr));
    const ctx = c.getContext("2d"), pad = this.pad * dpr;
    ctx.clearRect(0, 0, c.width, c.height);
    if (!this.colorStops.length) return;
    const grad = ctx.createLinearGradient(pad, 0, c.width - pad, 0);
    for (const [pos, r, g, b] of this.colorStops) {
      const to255 = (v) => Math.round(255 * Math.min(1, Math.max(0, v)));
      grad.addColorStop(Math.min(1, Math.max(0, pos)), `rgb(${to255(r)}, ${to255(g)}, ${to255(b)})`);
    }
    ctx.fillStyle = grad;
    ctx.fillRect(pad, 0, c.width - 2 * pad, c.height);
  }
};
