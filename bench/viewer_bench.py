"""Browser benchmark of `vnr view`: what a user of the page gets, measured through the page itself.

  /usr/bin/python3 bench/viewer_bench.py --model M.vnr [--volume V] [--size 512] [--seconds 10] [--train]

- orbit: frames/s of network images received while a drag orbits the camera (pointer events
  dispatched at 60 Hz on the canvas; coarse frames count);
- refine: time from releasing a drag to the first refined full-resolution frame (median of several);
- latency: from sending a camera change to the first frame whose version is at least that of the
  state reflecting it (while orbiting: coarse frames; single still changes: the first refined frame);
- with --train (needs --volume): training samples/s the page reports while frames keep coming, next
  to `vnr train VOLUME --steps N` run here.
Prints a markdown table and one JSON line. VNR_CLI names the vnr binary (default build/vnr)."""
import argparse
import json
import os
import statistics
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests", "browser"))
import harness  # noqa: E402

BATCH = 65536  # `vnr view`'s default batch

# In the page: a synthetic left-button drag on #canvas-main, one pointermove per 1/60 s.
DRAG_JS = """
const [seconds, dx, done] = arguments;
const el = document.getElementById('canvas-main'), r = el.getBoundingClientRect();
let x = r.left + r.width / 2, y = r.top + r.height / 2;
const ev = (type) => new PointerEvent(type, {pointerId: 7, pointerType: 'mouse', button: 0,
  buttons: type === 'pointerup' ? 0 : 1, clientX: x, clientY: y, bubbles: true, isPrimary: true});
el.dispatchEvent(ev('pointerdown'));
const start = performance.now();
const timer = setInterval(() => {
  x += dx; el.dispatchEvent(ev('pointermove'));
  if (performance.now() - start >= seconds * 1000) {
    clearInterval(timer);
    el.dispatchEvent(ev('pointerup'));
    done(performance.now());
  }
}, 1000 / 60);
"""


def frames_of(trace, view="network"):
    return [e for e in trace if e["kind"] == "frame" and e["header"]["view"] == view]


def camera_latencies(trace):
    """Per camera message sent: ms until the first frame rendered with a state that reflects it."""
    states = [e for e in trace if e["kind"] == "state"]
    frames = frames_of(trace)
    out = []
    for send in (e for e in trace if e["kind"] == "send" and e["msg"].get("type") == "camera"):
        eye = send["msg"]["eye"]
        state = next((s for s in states if s["t"] >= send["t"] and
                      all(abs(a - b) < 1e-3 for a, b in zip(s["camera"]["eye"], eye))), None)
        if not state:
            continue
        frame = next((f for f in frames if f["t"] >= send["t"] and f["header"]["version"] >= state["version"]), None)
        if frame:
            out.append(frame["t"] - send["t"])
    return out


def start_trace(b):
    b.js("vnrViewer.tracing = true;")


def take_trace(b):
    trace = b.js("const t = vnrViewer.trace; vnrViewer.tracing = false; return t;")
    return trace


def orbit(b, seconds):
    """Frames/s during a drag of `seconds`, the coarse share, and the latencies of its camera messages."""
    b.driver.set_script_timeout(seconds + 30)
    start_trace(b)
    t0 = b.js("return performance.now();")
    t1 = b.driver.execute_async_script(DRAG_JS, seconds, 3)
    trace = take_trace(b)
    during = [f for f in frames_of(trace) if t0 <= f["t"] <= t1]
    coarse = sum(1 for f in during if not f["header"]["refined"])
    return {"fps": len(during) / ((t1 - t0) / 1000), "frames": len(during), "coarse": coarse,
            "latency_ms": camera_latencies([e for e in trace if e["t"] <= t1])}


def release_to_refined(b, repeats):
    """ms from the drag's release to the first refined full-size frame of the final camera."""
    out = []
    b.driver.set_script_timeout(60)
    for _ in range(repeats):
        start_trace(b)
        released = b.driver.execute_async_script(DRAG_JS, 0.5, 4)
        b.wait("(() => { const s = vnrViewer.state, h = vnrViewer.lastHeader.network;"
               " return h && h.refined && h.version >= s.version && h.width === s.viewport.width; })()", 60)
        time.sleep(0.05)
        trace = take_trace(b)
        last_cam = [e for e in trace if e["kind"] == "send" and e["msg"].get("type") == "camera"][-1]
        state = next(s for s in trace if s["kind"] == "state" and s["t"] >= last_cam["t"] and
                     all(abs(a - c) < 1e-3 for a, c in zip(s["camera"]["eye"], last_cam["msg"]["eye"])))
        # With the brick cache every frame is full size: the final camera's may come before the release.
        frame = next((f for f in frames_of(trace) if f["header"]["refined"] and f["header"]["version"] >= state["version"]), None)
        if frame is None:  # that frame arrived before the trace caught the state: this repeat does not count
            continue
        out.append(max(0.0, frame["t"] - released))
    return out


def cold_fill(b, timeout=120):
    """From the page's first traced network frame to the first whose brick cache waits for nothing: seconds,
    frames meanwhile, and the bricks then resident (the cold cache filling while the view is still)."""
    start_trace(b)
    b.wait("(() => { const h = vnrViewer.lastHeader.network;"
           " return h && h.cache && h.cache.bricks > 0 && h.cache.pending === 0 && h.cache.stale === 0; })()", timeout)
    frames = frames_of(take_trace(b))
    done = next(f for f in frames if f["header"]["cache"] and f["header"]["cache"]["pending"] == 0
                and f["header"]["cache"]["bricks"] > 0)
    seconds = (done["t"] - frames[0]["t"]) / 1000
    n = sum(1 for f in frames if f["t"] <= done["t"])
    return {"seconds": seconds, "frames": n, "bricks": done["header"]["cache"]["bricks"]}


def still_latencies(b, repeats):
    """ms from one still camera change (interacting false) to its first frame."""
    out = []
    for i in range(repeats):
        b.wait("(() => { const s = vnrViewer.state, h = vnrViewer.lastHeader.network;"
               " return h && h.version >= s.version; })()", 60)
        start_trace(b)
        b.js("const c = vnrViewer.state.camera, k = arguments[0];"
             " vnrViewer.send({type: 'camera', eye: [c.eye[0] + k, c.eye[1], c.eye[2]], center: c.center,"
             " up: c.up, fovy: c.fovy, interacting: false});", 0.5 if i % 2 == 0 else -0.5)
        b.wait("vnrViewer.trace.some(e => e.kind === 'frame' && e.header.view === 'network' &&"
               " e.header.version >= vnrViewer.state.version && vnrViewer.state.version > vnrViewer.stateVersionSent())", 60)
        out.extend(camera_latencies(take_trace(b)))
    return out


def training(b, vnr, volume, config, seconds, work):
    """(samples/s the page reports while training, samples/s over wall time (steps the page saw x batch /
    seconds: what training keeps while frames come), page frames/s, `vnr train` samples/s)."""
    b.js("vnrViewer.send({type: 'train', action: 'start'});")
    b.wait("vnrViewer.state.training.state === 'running'", 30)
    time.sleep(2)  # past the first chunk and probe
    start_trace(b)
    reported = []
    step0, t0 = b.js("return vnrViewer.state.training.step;"), time.monotonic()
    end = t0 + seconds
    while time.monotonic() < end:
        time.sleep(0.5)
        reported.append(b.js("return vnrViewer.state.training.samples_per_second;"))
    wall = (b.js("return vnrViewer.state.training.step;") - step0) * BATCH / (time.monotonic() - t0)
    trace = take_trace(b)
    frames = frames_of(trace)
    fps = len(frames) / seconds
    split = {k: statistics.median(f["header"][k] for f in frames) if frames else 0 for k in ("render_ms", "train_ms")}
    b.js("vnrViewer.send({type: 'train', action: 'pause'});")
    report = os.path.join(work, "train.json")
    steps = b.js("return vnrViewer.state.training.step;") or 100
    harness.run_vnr(vnr, "train", volume, "--config", config, "--steps", max(100, min(steps, 1000)),
                    "-o", os.path.join(work, "bench.vnr"), "--no-ssim", "--report", report, "-q")
    with open(report) as f:
        cli = json.load(f)["samples_per_second"]
    page = statistics.median(reported[len(reported) // 2:]) if reported else 0
    return page, wall, fps, cli, split


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", required=True)
    p.add_argument("--volume", help="ground truth (needed for --train)")
    p.add_argument("--size", type=int, default=512, help="viewport WxW")
    p.add_argument("--seconds", type=float, default=10, help="orbit (and training) duration")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--train", action="store_true")
    p.add_argument("--cache-dims", help="X,Y,Z: `vnr view --cache-dims` (the model seen at another resolution)")
    p.add_argument("--config", default="paper", help="config of the `vnr train` comparison")
    args = p.parse_args()
    vnr = harness.vnr_or_exit("viewer_bench")
    if args.train and not args.volume:
        sys.exit("viewer_bench: --train needs --volume")
    work = tempfile.mkdtemp(prefix="vnr-viewer-bench-")
    server = harness.ViewServer(vnr, args.model, *(["--ground-truth", args.volume] if args.volume else []),
                                *(["--cache-dims", args.cache_dims] if args.cache_dims else []))
    b = harness.Browser()
    results = {"size": args.size}
    try:
        b.open_viewer(server.url)
        cold = cold_fill(b)
        results.update(cold_seconds=cold["seconds"], cold_frames=cold["frames"], cold_bricks=cold["bricks"])
        b.js("vnrViewer.send({type: 'view', layout: 'network'});")
        # The page answers a new layout with its own viewport: the benchmark's goes after that one.
        b.wait("vnrViewer.state.view.layout === 'network'", 30)
        time.sleep(1)
        b.js(f"vnrViewer.send({{type: 'viewport', width: {args.size}, height: {args.size}}});")
        b.wait(f"vnrViewer.state.viewport.width === {args.size} && vnrViewer.state.view.layout === 'network'", 30)
        b.wait_settled(120)
        o = orbit(b, args.seconds)
        results.update(orbit_fps=o["fps"], orbit_frames=o["frames"], orbit_coarse=o["coarse"],
                       orbit_latency_ms=statistics.median(o["latency_ms"]) if o["latency_ms"] else None)
        refine = release_to_refined(b, args.repeats)
        results["release_to_refined_ms"] = statistics.median(refine)
        still = still_latencies(b, args.repeats)
        results["still_latency_ms"] = statistics.median(still) if still else None
        if args.train:
            page, wall, fps, cli, split = training(b, vnr, args.volume, args.config, args.seconds, work)
            results.update(train_page_samples_per_s=page, train_wall_samples_per_s=wall, train_fps=fps,
                           train_cli_samples_per_s=cli, train_frame_render_ms=split["render_ms"],
                           train_frame_train_ms=split["train_ms"])
    finally:
        b.quit()
        server.terminate()
    rows = [("frames/s while orbiting", f"{results['orbit_fps']:.1f} ({results['orbit_coarse']} of "
             f"{results['orbit_frames']} coarse)"),
            ("cold brick cache at the page's first view: complete after (frames meanwhile, bricks)",
             f"{results['cold_seconds']:.2f} s ({results['cold_frames']} frames, {results['cold_bricks']} bricks)"),
            ("input-to-frame latency while orbiting (median)", f"{results['orbit_latency_ms'] or 0:.0f} ms"),
            ("release to first refined frame (median)", f"{results['release_to_refined_ms']:.0f} ms"),
            ("still camera change to its first frame (median)", f"{results['still_latency_ms'] or 0:.0f} ms")]
    if args.train:
        rows += [("training samples/s in the viewer while training (page)",
                  f"{results['train_page_samples_per_s'] / 1e6:.2f} M"),
                 ("training samples/s in the viewer over wall time", f"{results['train_wall_samples_per_s'] / 1e6:.2f} M"
                  f" ({100 * results['train_wall_samples_per_s'] / results['train_cli_samples_per_s']:.0f}% of `vnr train`)"
                  f" at {results['train_fps']:.1f} frames/s"),
                 ("a frame while training (medians): rendering, training",
                  f"{results['train_frame_render_ms']:.0f} ms, {results['train_frame_train_ms']:.0f} ms"),
                 ("training samples/s of `vnr train`", f"{results['train_cli_samples_per_s'] / 1e6:.2f} M")]
    print(f"| viewer, {args.size}x{args.size}, {os.path.basename(args.model)} | |\n|---|---|")
    for name, value in rows:
        print(f"| {name} | {value} |")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
