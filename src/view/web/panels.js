// The side panel: render settings, the TF controls around the editor, training (with the loss
// curve), slices and time series. Controls send partial updates and show only what the server's
// state says (a control the user is editing is left alone until the edit ends).
"use strict";
window.VNR = window.VNR || {};

VNR.$ = (id) => document.getElementById(id);

// Calls fn with the latest arguments at most once per animation frame.
VNR.perFrame = (fn) => {
  let request = 0, args = null;
  return (...a) => {
    args = a;
    if (!request) request = requestAnimationFrame(() => { request = 0; fn(...args); });
  };
};

// Marks inputs being edited (typed into, slider held) so incoming state does not overwrite them.
VNR.trackEditing = (el) => {
  el.addEventListener("input", () => { el.dataset.editing = "1"; });
  el.addEventListener("change", () => { delete el.dataset.editing; });
  el.addEventListener("blur", () => { delete el.dataset.editing; });
};

VNR.setControl = (id, value) => {
  const el = VNR.$(id);
  if (!el || el.dataset.editing) return;
  // State numbers are float32 on the server: 0.2 arrives as 0.20000000298..., shown as 0.2.
  if (typeof value === "number" && !Number.isInteger(value)) value = Number(value.toPrecision(6));
  if (el.type === "checkbox") el.checked = !!value;
  else if (String(el.value) !== String(value)) el.value = value;
};

VNR.format = (v, digits = 3) => (typeof v === "number" && isFinite(v) ? Number(v.toPrecision(digits)).toString() : "–");
// Large counts with a unit prefix: 13500000 -> "13.5 M".
VNR.formatCount = (v) => {
  if (typeof v !== "number" || !isFinite(v)) return "–";
  for (const [scale, prefix] of [[1e9, " G"], [1e6, " M"], [1e3, " k"]]) if (Math.abs(v) >= scale) return VNR.format(v / scale) + prefix;
  return VNR.format(v);
};

VNR.Panels = class {
  constructor(send, tfEditor) {
    this.send = send;
    this.tfEditor = tfEditor;
    this.info = null;
    this.state = null;
    this.losses = [];
    this.psnr = [];
    this.timestepMarks = [];   // training steps at which the target timestep changed
    this.stepHistory = [];     // [time ms, step] for steps/s
    this.colorKey = "";
    this.colorFetch = 0;
    document.querySelectorAll("#panel input, #panel select").forEach(VNR.trackEditing);
    this.bindView();
    this.bindRender();
    this.bindTf();
    this.bindTraining();
    this.bindSlicesAndTime();
    new ResizeObserver(() => this.drawLosses()).observe(VNR.$("loss-canvas"));
  }

  // An input's number, or null (nothing is sent) when it is not one.
  number(id, integer = false) {
    const v = integer ? parseInt(VNR.$(id).value, 10) : parseFloat(VNR.$(id).value);
    return Number.isFinite(v) ? v : null;
  }
  onNumber(id, make, integer = false) {
    VNR.$(id).addEventListener("change", () => {
      const v = this.number(id, integer);
      if (v !== null) this.send(make(v));
    });
  }

  bindView() {
    VNR.$("layout").addEventListener("change", (e) => this.send({ type: "view", layout: e.target.value }));
    VNR.$("reset-camera").addEventListener("click", () => this.send({ type: "reset_camera" }));
  }

  bindRender() {
    for (const key of ["mode", "strategy", "macrocells"]) {
      VNR.$(`render-${key}`).addEventListener("change", (e) => this.send({ type: "render", [key]: e.target.value }));
    }
    VNR.$("render-shade").addEventListener("change", (e) => this.send({ type: "render", shade: e.target.checked }));
    this.onNumber("render-step", (v) => ({ type: "render", step: v }));
    this.onNumber("render-density", (v) => ({ type: "render", density: v }));
    this.onNumber("render-max-frames", (v) => ({ type: "render", max_frames: v }), true);
    this.onNumber("render-coarse-scale", (v) => ({ type: "render", coarse_scale: v }), true);
    const sendLight = VNR.perFrame(() => {
      const az = (this.number("light-azimuth") * Math.PI) / 180, el = (this.number("light-elevation") * Math.PI) / 180;
      this.send({ type: "render", light: [Math.cos(el) * Math.sin(az), Math.sin(el), Math.cos(el) * Math.cos(az)] });
    });
    VNR.$("light-azimuth").addEventListener("input", sendLight);
    VNR.$("light-elevation").addEventListener("input", sendLight);
  }

  bindTf() {
    VNR.$("tf-colormap").addEventListener("change", (e) => this.send({ type: "tf", colormap: e.target.value }));
    VNR.$("tf-max-opacity").addEventListener("change", () => {
      const v = this.number("tf-max-opacity");
      if (v !== null && v > 0) this.tfEditor.setMaxOpacity(v);
    });
    const sendRange = () => {
      const lo = this.number("tf-range-lo"), hi = this.number("tf-range-hi");
      if (lo !== null && hi !== null) this.send({ type: "tf", range: [lo, hi] });
    };
    VNR.$("tf-range-lo").addEventListener("change", sendRange);
    VNR.$("tf-range-hi").addEventListener("change", sendRange);
    VNR.$("tf-load").addEventListener("change", (e) => {
      const file = e.target.files[0];
      if (!file) return;
      file.text().then((text) => this.send({ type: "tf_load", text }));
      e.target.value = "";
    });
  }

  bindTraining() {
    VNR.$("train-start").addEventListener("click", () => this.send({ type: "train", action: "start" }));
    VNR.$("train-pause").addEventListener("click", () => this.send({ type: "train", action: "pause" }));
    VNR.$("train-reset").addEventListener("click", () => {
      const lr = this.number("train-lr"), msg = { type: "train", action: "reset" };
      if (lr !== null && lr > 0) msg.learning_rate = lr;
      this.send(msg);
    });
    this.onNumber("train-budget", (ms) => ({ type: "train", budget: ms / 1000 }));
    VNR.$("save-model").addEventListener("click", () => {
      VNR.$("save-status").textContent = "saving…";
      this.send({ type: "save", name: VNR.$("save-name").value.trim() });
    });
  }

  bindSlicesAndTime() {
    VNR.$("slice-toggle").addEventListener("change", (e) => this.send({ type: "view", slice: e.target.checked }));
    VNR.$("slice-axis").addEventListener("change", (e) => this.send({ type: "view", slice_axis: parseInt(e.target.value, 10) }));
    const sendPosition = VNR.perFrame(() => this.send({ type: "view", slice_position: this.number("slice-position") }));
    VNR.$("slice-position").addEventListener("input", sendPosition);
    VNR.$("timestep").addEventListener("change", () => this.send({ type: "timestep", index: this.number("timestep", true) }));
    const sendContinuous = () => {
      const msg = { type: "timestep", continuous: VNR.$("timestep-continuous").checked };
      const every = this.number("timestep-switch-every", true);
      if (every !== null) msg.switch_every = every;
      this.send(msg);
    };
    VNR.$("timestep-continuous").addEventListener("change", sendContinuous);
    VNR.$("timestep-switch-every").addEventListener("change", sendContinuous);
  }

  setInfo(info) {
    this.info = info;
    VNR.$("description").textContent = info.description || "";
    VNR.$("info").textContent = JSON.stringify(info, null, 1);
    VNR.$("train-panel").hidden = !info.can_train;
    VNR.$("time-panel").hidden = !(info.n_timesteps > 1);
    VNR.$("timestep").max = Math.max(0, (info.n_timesteps || 1) - 1);
    const select = VNR.$("tf-colormap");
    select.replaceChildren(...(info.colormaps || []).concat(["custom"]).map((name) => new Option(name, name)));
    const save = VNR.$("save-model");
    save.disabled = !info.save_dir;
    save.title = info.save_dir ? `Writes into ${info.save_dir}` : "Saving is off: start vnr view with --save-dir DIR";
    this.losses = [];
    this.psnr = [];
    this.timestepMarks = [];
  }

  setState(s) {
    const prev = this.state;
    this.state = s;
    VNR.setControl("layout", s.view.layout);
    const r = s.render;
    VNR.setControl("render-mode", r.mode);
    VNR.setControl("render-strategy", r.strategy);
    VNR.setControl("render-macrocells", r.macrocells);
    VNR.setControl("render-step", r.step);
    VNR.setControl("render-shade", r.shade);
    VNR.setControl("render-density", r.density);
    VNR.setControl("render-max-frames", r.max_frames);
    VNR.setControl("render-coarse-scale", r.coarse_scale);
    const [lx, ly, lz] = r.light;
    VNR.setControl("light-azimuth", Math.round((Math.atan2(lx, lz) * 180) / Math.PI));
    VNR.setControl("light-elevation", Math.round((Math.asin(Math.max(-1, Math.min(1, ly))) * 180) / Math.PI));
    this.setTfState(s.tf);
    VNR.setControl("slice-toggle", s.view.slice);
    VNR.setControl("slice-axis", s.view.slice_axis);
    VNR.setControl("slice-position", s.view.slice_position);
    this.setTrainingState(s.training, prev && prev.training);
  }

  setTfState(tf) {
    VNR.setControl("tf-colormap", tf.colormap);
    VNR.setControl("tf-range-lo", tf.range[0]);
    VNR.setControl("tf-range-hi", tf.range[1]);
    const units = (x) => (this.info ? `(${VNR.format(this.info.lo + x * (this.info.hi - this.info.lo), 4)})` : "");
    VNR.$("tf-range-lo-units").textContent = units(tf.range[0]);
    VNR.$("tf-range-hi-units").textContent = units(tf.range[1]);
    // Opacity above the curve's top: raise the top so every point stays visible.
    const top = Math.max(0, ...tf.opacity.map((p) => p[1]));
    if (top > this.tfEditor.maxOpacity) {
      this.tfEditor.setMaxOpacity(Math.min(1, Math.ceil(top * 100) / 100));
      VNR.setControl("tf-max-opacity", this.tfEditor.maxOpacity);
    }
    this.tfEditor.setState(tf);
    this.updateColorbar(tf);
  }

  // The colour bar across the TF window: custom colours directly, a preset's from the server's TF
  // file (/tf.json), whose colour controls span the whole normalised range.
  updateColorbar(tf) {
    const key = JSON.stringify([tf.colormap, tf.custom_colors, tf.range]);
    if (key === this.colorKey) return;
    this.colorKey = key;
    if (tf.colormap === "custom") {
      const n = tf.custom_colors.length;
      this.tfEditor.setColorStops(tf.custom_colors.map((c, i) => [n > 1 ? i / (n - 1) : 0, ...c]));
      return;
    }
    const ticket = ++this.colorFetch;
    fetch(VNR.url("/tf.json"))
      .then((r) => (r.ok ? r.json() : null))
      .then((j) => {
        if (!j || ticket !== this.colorFetch) return;
        const [lo, hi] = tf.range, span = Math.max(1e-9, hi - lo);
        const stops = VNR.colorStopsOf(j).map(([p, ...c]) => [(p - lo) / span, ...c]);
        this.tfEditor.setColorStops(stops.filter((s) => s[0] >= 0 && s[0] <= 1));
      })
      .catch(() => {});
  }

  setTrainingState(t, prev) {
    VNR.setControl("train-budget", Math.round(t.budget * 1000));
    VNR.setControl("timestep", t.timestep);
    VNR.$("timestep-value").textContent = `${t.timestep}`;
    VNR.setControl("timestep-continuous", t.continuous);
    VNR.setControl("timestep-switch-every", t.switch_every);
    if (prev && prev.timestep !== t.timestep) this.timestepMarks.push(t.step);
    if (t.n_losses < this.losses.length) { // reset: the history starts again
      this.losses.length = t.n_losses;
      this.psnr = this.psnr.filter((p) => p[0] < t.n_losses);
      this.timestepMarks = this.timestepMarks.filter((s) => s <= t.step);
    }
    const now = performance.now();
    this.stepHistory.push([now, t.step]);
    while (this.stepHistory.length > 2 && this.stepHistory[0][0] < now - 3000) this.stepHistory.shift();
    const [t0, s0] = this.stepHistory[0];
    const stepsPerSecond = now > t0 && t.step >= s0 ? ((t.step - s0) * 1000) / (now - t0) : 0;
    VNR.$("train-state").textContent = t.state;
    VNR.$("train-step").textContent = `${t.step}`;
    VNR.$("train-loss").textContent = t.step > 0 ? VNR.format(t.loss, 4) : "–";
    VNR.$("train-psnr").textContent = t.psnr > 0 ? `${t.psnr.toFixed(2)} dB` : "–";
    VNR.$("train-steps-per-second").textContent = t.state === "running" ? VNR.format(stepsPerSecond, 3) : "0";
    VNR.$("train-samples-per-second").textContent = VNR.formatCount(t.samples_per_second);
    VNR.$("train-learning-rate").textContent = VNR.format(t.learning_rate, 3);
    VNR.$("train-seconds").textContent = t.seconds.toFixed(1);
    VNR.$("train-start").disabled = t.state === "running" || t.state === "unavailable";
    VNR.$("train-pause").disabled = t.state !== "running";
  }

  onLosses(msg) {
    if (msg.from > this.losses.length) this.losses.push(...new Array(msg.from - this.losses.length).fill(NaN));
    this.losses.length = msg.from;
    this.losses.push(...msg.values);
    if (msg.psnr) this.psnr = msg.psnr;
    this.drawLosses();
  }

  onSaved(msg) { VNR.$("save-status").textContent = `saved ${msg.path}`; }
  onSaveFailed() { if (VNR.$("save-status").textContent === "saving…") VNR.$("save-status").textContent = ""; }

  // Loss on a log axis (left), PSNR estimates as dots (right axis), timestep switches as lines.
  drawLosses() {
    const c = VNR.$("loss-canvas"), dpr = window.devicePixelRatio || 1;
    c.width = Math.max(1, Math.round(c.clientWidth * dpr));
    c.height = Math.max(1, Math.round(c.clientHeight * dpr));
    const ctx = c.getContext("2d"), w = c.width, h = c.height, pad = 4 * dpr;
    ctx.clearRect(0, 0, w, h);
    const values = this.losses, n = values.length;
    if (n < 2) return;
    const logs = values.filter((v) => v > 0).map(Math.log10);
    if (!logs.length) return;
    const lo = Math.min(...logs), hi = Math.max(...logs), span = Math.max(1e-6, hi - lo);
    const xOf = (i) => pad + (i / (n - 1)) * (w - 2 * pad);
    ctx.strokeStyle = "rgba(255, 200, 0, 0.6)";
    for (const s of this.timestepMarks) {
      ctx.beginPath(); ctx.moveTo(xOf(s), 0); ctx.lineTo(xOf(s), h); ctx.stroke();
    }
    ctx.strokeStyle = "#4c9be8";
    ctx.lineWidth = dpr;
    ctx.beginPath();
    const stride = Math.max(1, Math.floor(n / w));
    for (let i = 0, started = false; i < n; i += stride) {
      if (!(values[i] > 0)) continue;
      const y = pad + (1 - (Math.log10(values[i]) - lo) / span) * (h - 2 * pad);
      if (started) ctx.lineTo(xOf(i), y); else { ctx.moveTo(xOf(i), y); started = true; }
    }
    ctx.stroke();
    ctx.fillStyle = "#9aa0aa";
    ctx.font = `${10 * dpr}px sans-serif`;
    ctx.fillText(`loss ${VNR.format(values[n - 1], 3)}`, pad, h - pad);
    if (!this.psnr.length) return;
    const dbs = this.psnr.map((p) => p[1]), dlo = Math.min(...dbs), dspan = Math.max(1, Math.max(...dbs) - dlo);
    ctx.fillStyle = "#6ad08a";
    for (const [step, db] of this.psnr) {
      ctx.beginPath();
      ctx.arc(xOf(Math.min(step, n - 1)), pad + (1 - (db - dlo) / dspan) * (h - 2 * pad), 2.5 * dpr, 0, 2 * Math.PI);
      ctx.fill();
    }
    ctx.fillText(`PSNR ${dbs[dbs.length - 1].toFixed(1)} dB`, w / 2, h - pad);
  }
};

// The colour stops of an instantvnr TF (or scene) file: colorControls [{position, color: {r, g, b}}].
VNR.colorStopsOf = (json) => {
  const find = (o) => {
    if (!o || typeof o !== "object") return null;
    if (Array.isArray(o.colorControls)) return o.colorControls;
    for (const v of Object.values(o)) { const r = find(v); if (r) return r; }
    return null;
  };
  const controls = find(json) || [];
  return controls.map((c) => [c.position, c.color.r, c.color.g, c.color.b]).sort((a, b) => a[0] - b[0]);
};
