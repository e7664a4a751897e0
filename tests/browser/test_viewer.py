"""Browser tests of `vnr view` (docs/VIEWER.md): headless Chromium drives the real page against the
real server on 127.0.0.1, and every image is checked against `vnr render` of the same scene.

Run: VNR_CLI=build/vnr /usr/bin/python3 tests/browser/test_viewer.py (ctest: browser_viewer).
Skips (exit 0, a SKIPPED line) without Selenium, Chromium or ChromeDriver.

PSNR thresholds were measured on this machine (2 cores, bf16 CPU inference): see the constants.
The whole file takes about 100 s on 2 cores."""
import json
import os
import shutil
import sys
import tempfile
import time
import unittest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402
from harness import Browser, ViewServer, log, render_args_of, render_psnr, run_vnr  # noqa: E402

# /screenshot.png (lossless) against `vnr render` of /scene.json with the state's settings: measured
# 62.7-63.4 dB (vnr render against itself: 63.6 dB; its threads sum in varying order, bf16 inference).
SCREENSHOT_PSNR = 50.0
# The page's canvas (the JPEG frame of quality 85, drawn 1:1) against `vnr render`: measured 38.0-42.9 dB.
CANVAS_PSNR = 33.0
# After a drag / mode switch / TF edit the earlier screenshot against the new render: measured 13-27 dB.
CHANGED_PSNR = 35.0

VNR = harness.find_vnr()
WORK = None
VOLUME = MODEL = None


def setUpModule():
    global WORK, VOLUME, MODEL
    WORK = tempfile.mkdtemp(prefix="vnr-browser-")
    VOLUME = os.path.join(WORK, "ml.json")
    MODEL = os.path.join(WORK, "ml.vnr")
    run_vnr(VNR, "synth", "marschner-lobb", "--dims", "64,64,64", "-o", VOLUME)
    run_vnr(VNR, "train", VOLUME, "--config", "small", "--steps", 200, "-o", MODEL, "-q")


def tearDownModule():
    shutil.rmtree(WORK, ignore_errors=True)


class ViewerTestCase(unittest.TestCase):
    """One `vnr view` and one browser per class; subclasses name the server's arguments."""

    @classmethod
    def server_args(cls):
        raise NotImplementedError

    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.mkdtemp(dir=WORK)
        cls.server = ViewServer(VNR, *cls.server_args())
        cls.browser = Browser()
        cls.browser.open_viewer(cls.server.url)

    @classmethod
    def tearDownClass(cls):
        cls.browser.quit()
        code, _ = cls.server.terminate()
        if code != 0:
            log(f"vnr view exited {code}: {''.join(cls.server.stderr_lines)}")

    def state(self):
        return self.browser.js("return vnrViewer.state;")

    def select(self, element_id, value):
        from selenium.webdriver.support.ui import Select
        Select(self.browser.driver.find_element("id", element_id)).select_by_value(value)

    def wait_state(self, condition, what, timeout=30):
        return self.browser.wait(f"(() => {{ const s = vnrViewer.state; return {condition}; }})()", timeout, what)

    def settled_screenshot(self, label):
        """/screenshot.png once the current settings are fully rendered."""
        self.browser.wait_settled()
        return self.server.fetch("/screenshot.png", os.path.join(self.dir, f"{label}-before.png"))

    def assert_matches_render(self, label, input_path, previous_shot=None):
        """Waits for the settled frame, then compares /screenshot.png and the canvas with `vnr render`
        of /scene.json; previous_shot: an earlier screenshot the render must differ from."""
        header = self.browser.wait_settled()
        state = self.state()
        scene = self.server.fetch("/scene.json", os.path.join(self.dir, f"{label}-scene.json"))
        shot = self.server.fetch("/screenshot.png", os.path.join(self.dir, f"{label}-shot.png"))
        canvas = self.browser.canvas_png("canvas-main", os.path.join(self.dir, f"{label}-canvas.png"))
        w, h, spp = header["width"], header["height"], header["accumulated"]
        extra = render_args_of(state)
        shot_db = render_psnr(VNR, input_path, scene, w, h, spp, shot, self.dir, extra)
        canvas_db = render_psnr(VNR, input_path, scene, w, h, spp, canvas, self.dir, extra)
        log(f"{label}: {w}x{h} spp {spp}: screenshot {shot_db:.2f} dB, canvas {canvas_db:.2f} dB vs vnr render")
        self.assertGreater(shot_db, SCREENSHOT_PSNR, f"{label}: /screenshot.png differs from vnr render")
        self.assertGreater(canvas_db, CANVAS_PSNR, f"{label}: the canvas differs from vnr render")
        if previous_shot:
            before_db = render_psnr(VNR, input_path, scene, w, h, spp, previous_shot, self.dir, extra)
            log(f"{label}: the previous screenshot vs the new render: {before_db:.2f} dB")
            self.assertLess(before_db, CHANGED_PSNR, f"{label}: the image did not change")
        return shot


class ModelView(ViewerTestCase):
    """A trained model with its ground truth: rendering matches `vnr render`, camera, mode, TF."""

    @classmethod
    def server_args(cls):
        return [MODEL, "--ground-truth", VOLUME]

    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        from selenium.webdriver.support.ui import Select
        Select(cls.browser.driver.find_element("id", "layout")).select_by_value("network")
        cls.browser.wait("vnrViewer.state.view.layout === 'network'", 10, "the network layout")

    def test_1_first_frame_matches_render(self):
        self.assertTrue(self.browser.js("return vnrViewer.frames.network > 0;"))
        self.assert_matches_render("first", MODEL)

    def test_2_drag_changes_camera(self):
        from selenium.webdriver.common.action_chains import ActionChains
        shot = self.settled_screenshot("drag")
        before = self.state()
        canvas = self.browser.driver.find_element("id", "canvas-main")
        self.browser.js("vnrViewer.tracing = true;")
        ActionChains(self.browser.driver).move_to_element(canvas).click_and_hold() \
            .move_by_offset(40, 0).move_by_offset(40, 15).move_by_offset(30, 10).release().perform()
        self.wait_state(f"s.version > {before['version']} && s.camera.eye[0] !== {before['camera']['eye'][0]}",
                        "the camera to change")
        # From the brick cache, frames stay at full resolution while the camera moves.
        frames = self.browser.js("const t = vnrViewer.trace; vnrViewer.tracing = false;"
                                 " return t.filter(e => e.kind === 'frame' && e.header.view === 'network')"
                                 ".map(e => [e.header.width, e.header.refined, e.header.cache !== null]);")
        width = self.state()["viewport"]["width"]
        self.assertTrue(frames, "frames came during the drag")
        self.assertTrue(all(f == [width, True, True] for f in frames), f"full-size cached frames: {frames[:5]}")
        self.assert_matches_render("drag", MODEL, previous_shot=shot)

    def test_3_shadow_mode(self):
        shot = self.settled_screenshot("shadow")
        self.select("render-mode", "shadow")
        self.wait_state("s.render.mode === 'shadow'", "shadow mode")
        self.assert_matches_render("shadow", MODEL, previous_shot=shot)

    def test_4_tf_point_drag(self):
        from selenium.webdriver.common.action_chains import ActionChains
        shot = self.settled_screenshot("tf")
        before = self.state()["tf"]["opacity"]
        # The last control point (x = 1) is dragged down to a quarter of the canvas height.
        b = self.browser
        rect = b.js("const r = document.getElementById('tf-canvas').getBoundingClientRect();"
                    " return [r.width, r.height];")
        max_opacity = float(b.js("return document.getElementById('tf-max-opacity').value;"))
        pad = 6
        x_last, y_last = before[-1]
        px = pad + x_last * (rect[0] - 2 * pad) - rect[0] / 2
        py = rect[1] - pad - (y_last / max_opacity) * (rect[1] - 2 * pad) - rect[1] / 2
        tf_canvas = b.driver.find_element("id", "tf-canvas")
        ActionChains(b.driver).move_to_element_with_offset(tf_canvas, int(px), int(py)).click_and_hold() \
            .move_by_offset(0, 20).move_by_offset(0, int(rect[1] * 0.3)).release().perform()
        after = self.wait_state(f"s.tf.opacity[s.tf.opacity.length - 1][1] < {y_last} - 0.05 && s.tf.opacity",
                                "the TF's last point to move down")
        self.assertEqual(len(after), len(before))
        self.assertAlmostEqual(after[-1][0], 1.0)
        self.assert_matches_render("tf", MODEL, previous_shot=shot)

    def test_5_layouts_size_the_viewport(self):
        b = self.browser
        area = b.js("const a = document.getElementById('views'); return [a.clientWidth, a.clientHeight];")
        self.select("layout", "side_by_side")
        # Side by side: each half is an image of half the area's width (device pixel ratio 1 here).
        self.wait_state(f"s.view.layout === 'side_by_side' && s.viewport.width === {round(area[0] / 2)}"
                        f" && s.viewport.height === {area[1]}", "half-width viewport")
        b.wait("vnrViewer.lastHeader.truth && vnrViewer.lastHeader.truth.version >= vnrViewer.state.version", 30,
               "a truth frame")
        self.assertFalse(b.js("return document.getElementById('canvas-truth').hidden;"))
        self.select("layout", "split")
        self.wait_state(f"s.view.layout === 'split' && s.viewport.width === {area[0]}", "full-width viewport")
        self.assertFalse(b.js("return document.getElementById('split-divider').hidden;"))
        # Dragging the divider to a quarter of the width sets the state's split.
        from selenium.webdriver.common.action_chains import ActionChains
        divider = b.driver.find_element("id", "split-divider")
        ActionChains(b.driver).click_and_hold(divider).move_by_offset(-area[0] // 8, 0) \
            .move_by_offset(-area[0] // 8, 0).release().perform()
        split = self.wait_state("Math.abs(s.view.split - 0.25) < 0.02 && s.view.split", "split 0.25")
        self.assertAlmostEqual(split, 0.25, delta=0.02)

    def test_6_slices(self):
        b = self.browser
        self.browser.driver.find_element("id", "slice-toggle").click()
        self.wait_state("s.view.slice", "slices on")
        self.assertFalse(b.js("return document.getElementById('slices').hidden;"))
        b.wait("['slice_truth', 'slice_network', 'slice_difference'].every(v => vnrViewer.lastHeader[v] &&"
               " vnrViewer.lastHeader[v].version >= vnrViewer.state.version)", 30, "the three slice images")
        # The slice strip takes height from the view area: the page sends the smaller viewport.
        height = b.js("return document.getElementById('views').clientHeight;")
        self.wait_state(f"s.viewport.height === {height}", "the viewport of the smaller area")
        header = b.js("return vnrViewer.lastHeader.slice_truth;")
        self.assertEqual((header["width"], header["height"]), (64, 64))  # the volume's xy plane (axis z)


class SeriesView(ViewerTestCase):
    """A time series: the time panel drives the target timestep."""

    @classmethod
    def server_args(cls):
        series = os.path.join(cls.dir, "series.json")
        run_vnr(VNR, "synth", "noise", "--dims", "32,32,32", "--timesteps", 3, "-o", series)
        return [series, "--config", "small"]

    def test_timestep_slider(self):
        b = self.browser
        self.assertFalse(b.js("return document.getElementById('time-panel').hidden;"))
        self.assertEqual(b.js("return document.getElementById('timestep').max;"), "2")
        b.js("const t = document.getElementById('timestep'); t.value = 2;"
             " t.dispatchEvent(new Event('change'));")
        version = self.wait_state("s.training.timestep === 2 && s.version", "timestep 2")
        b.wait(f"vnrViewer.lastHeader.truth && vnrViewer.lastHeader.truth.version >= {version}", 30,
               "a truth frame of timestep 2")
        self.assertEqual(self.browser.js("return document.getElementById('timestep-value').textContent;"), "2")


class TrainingView(ViewerTestCase):
    """A volume trained from the page; access rules, bad messages, two browsers, SIGTERM."""

    @classmethod
    def server_args(cls):
        return [VOLUME, "--config", "small", "--save-dir", cls.dir]

    def click(self, element_id):
        self.browser.driver.find_element("id", element_id).click()

    def text(self, element_id):
        return self.browser.js(f"return document.getElementById('{element_id}').textContent;")

    def test_1_training_lowers_loss(self):
        b = self.browser
        self.assertTrue(b.js("return !document.getElementById('train-panel').hidden;"))
        self.click("train-start")
        self.wait_state("s.training.state === 'running'", "training to run")
        b.wait("vnrViewer.losses.length >= 2", 30, "the first losses")
        first_loss = b.js("return vnrViewer.losses[0];")
        first_psnr = b.wait("vnrViewer.psnr.length > 0 && vnrViewer.psnr[0][1]", 60, "a PSNR estimate")
        b.wait(f"vnrViewer.psnr.length > 1 && vnrViewer.psnr[vnrViewer.psnr.length - 1][1] > {first_psnr} + 0.5",
               90, "the PSNR estimate to rise")
        shown_loss = float(self.text("train-loss"))
        shown_psnr = float(self.text("train-psnr").split()[0])
        log(f"training: first loss {first_loss:.4f} -> shown {shown_loss:.4f}; "
            f"first PSNR {first_psnr:.2f} dB -> shown {shown_psnr:.2f} dB at step {self.text('train-step')}")
        self.assertLess(shown_loss, first_loss)
        self.assertGreater(shown_psnr, first_psnr)

    def test_2_pause_stops_steps(self):
        self.click("train-start")
        self.wait_state("s.training.state === 'running'", "training to run")
        self.click("train-pause")
        self.wait_state("s.training.state === 'paused'", "training to pause")
        time.sleep(0.2)  # a state message in flight
        first = self.text("train-step")
        time.sleep(1)
        self.assertEqual(self.text("train-step"), first)
        self.assertGreater(int(first), 0)

    def test_3_save_model(self):
        b = self.browser
        name = b.driver.find_element("id", "save-name")
        name.clear()
        name.send_keys("from_page")
        self.click("save-model")
        status = b.wait("document.getElementById('save-status').textContent.startsWith('saved ') &&"
                        " document.getElementById('save-status').textContent", 30, "the saved reply")
        path = status[len("saved "):]
        self.assertEqual(os.path.dirname(os.path.abspath(path)), os.path.abspath(self.dir))
        self.assertTrue(path.endswith("from_page.vnr"))
        run_vnr(VNR, "info", path)
        report = os.path.join(self.dir, "eval.json")
        run_vnr(VNR, "eval", path, VOLUME, "--no-ssim", "--report", report, "-q")
        with open(report) as f:
            psnr = json.load(f)["psnr"]
        log(f"saved model: vnr eval PSNR {psnr:.2f} dB")
        self.assertGreater(psnr, 20.0)

    def test_4_access_needs_the_token(self):
        s = self.server
        for path in ("/", "/viewer.js", "/scene.json", "/screenshot.png"):
            self.assertEqual(s.get(path, token=False)[0], 403, path)
            self.assertEqual(s.get(path, token="0" * 32)[0], 403, path)
        status, body = s.get("/")
        self.assertEqual(status, 200)
        self.assertIn(b"vnr view", body)
        # A WebSocket from the page with a wrong token (and no cookie) is refused: no hello.
        b = self.browser
        b.driver.delete_all_cookies()
        probe = ("const [token, done] = arguments; const seen = {open: false, messages: 0, closed: false};"
                 " const ws = new WebSocket(`ws://${location.host}/ws?token=${token}`);"
                 " ws.onopen = () => { seen.open = true; }; ws.onmessage = () => { seen.messages++; };"
                 " ws.onerror = () => { seen.error = true; }; ws.onclose = () => { seen.closed = true; };"
                 " setTimeout(() => { ws.close(); done(seen); }, 1500);")
        b.driver.set_script_timeout(10)
        wrong = b.driver.execute_async_script(probe, "f" * 32)
        self.assertEqual((wrong["open"], wrong["messages"], wrong["closed"]), (False, 0, True), wrong)
        right = b.driver.execute_async_script(probe, s.token)  # the same probe with the token gets hello
        self.assertTrue(right["open"] and right["messages"] >= 1, right)

    def test_5_malformed_messages(self):
        b = self.browser
        before = self.state()
        n_errors = b.js("return vnrViewer.errors.length;")
        for msg in ("{not json", '{"type": "no_such_type"}', '"just a string"', '{"type": "render", "step": "fast"}',
                    '{"type": "render", "mode": "xray"}', '{"type": "viewport", "width": 1, "height": 1}',
                    '{"type": "camera", "eye": [1, 2]}', '{"type": "tf", "opacity": [[0.5]]}'):
            b.js("vnrViewer.send(arguments[0]);", msg)
        errors = b.wait(f"vnrViewer.errors.length >= {n_errors + 8} && vnrViewer.errors", 10, "8 error replies")
        self.assertTrue(b.js("return !document.getElementById('error').hidden;"))
        self.assertEqual(self.text("error-text"), errors[-1])
        log(f"error replies: {errors[n_errors:]}")
        after = self.state()
        self.assertEqual((after["render"], after["viewport"], after["camera"]),
                         (before["render"], before["viewport"], before["camera"]))
        self.click("error-close")
        self.assertTrue(b.js("return document.getElementById('error').hidden;"))
        # The server is alive: a change through the page still produces frames.
        step = b.driver.find_element("id", "render-step")
        step.clear()
        step.send_keys("2\n")
        version = self.wait_state("s.render.step === 2 && s.version", "render step 2")
        b.wait(f"vnrViewer.lastHeader.network.version >= {version}", 30, "a frame with the new step")

    def test_6_two_browsers(self):
        other = Browser()
        try:
            other.open_viewer(self.server.url)
            self.select("tf-colormap", "gray")
            version = other.wait("vnrViewer.state.tf.colormap === 'gray' && vnrViewer.state.version", 10,
                                 "the other browser to see the colour map")
            self.assertEqual(other.js("return document.getElementById('tf-colormap').value;"), "gray")
            other.wait(f"vnrViewer.lastHeader.network && vnrViewer.lastHeader.network.version >= {version}", 30,
                       "the other browser's frame of the change")
            from selenium.webdriver.support.ui import Select
            Select(other.driver.find_element("id", "render-mode")).select_by_value("shadow")
            self.wait_state("s.render.mode === 'shadow'", "this browser to see shadow mode")
            self.assertEqual(self.browser.js("return document.getElementById('render-mode').value;"), "shadow")
            v = self.state()["version"]
            self.browser.wait(f"vnrViewer.lastHeader.network.version >= {v}", 30, "this browser's frame")
        finally:
            other.quit()

    def test_9_sigterm_stops_cleanly(self):
        self.click("train-start")
        self.wait_state("s.training.state === 'running'", "training to run")
        code, seconds = self.server.terminate(timeout=5)
        stderr = "".join(self.server.stderr_lines)
        log(f"SIGTERM while training: exit {code} after {seconds:.2f} s")
        self.assertEqual(code, 0, stderr)
        self.assertLess(seconds, 5)
        self.assertIn("vnr view: stopped", stderr)
        self.browser.wait("!vnrViewer.connected", 10, "the page to see the connection close")
        self.assertFalse(self.browser.js("return document.getElementById('conn-banner').hidden;"))


if __name__ == "__main__":
    why = harness.missing_tools() or ("" if VNR else "no vnr binary (set VNR_CLI)")
    if why:
        print(f"SKIPPED: browser tests: {why}")
        sys.exit(0)
    unittest.main(verbosity=2)
