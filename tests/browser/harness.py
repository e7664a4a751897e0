"""What the browser tests and bench/viewer_bench.py share: the `vnr view` process, headless Chromium
through Selenium, waiting on the page's window.vnrViewer, and image comparison through `vnr render
--reference` (Debian's /usr/bin/python3 has Selenium but no NumPy or Pillow)."""
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.parse
import urllib.request

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"


def missing_tools():
    """Why the browser harness cannot run here ("" when it can)."""
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "python3-selenium is not installed (run scripts/setup.sh; use /usr/bin/python3)"
    for path in (CHROMIUM, CHROMEDRIVER):
        if not os.access(path, os.X_OK):
            return f"{path} is missing (run scripts/setup.sh)"
    return ""


def find_vnr():
    """The vnr binary: $VNR_CLI, else build/vnr of this checkout."""
    path = os.environ.get("VNR_CLI") or os.path.join(os.path.dirname(__file__), "..", "..", "build", "vnr")
    return os.path.abspath(path) if os.access(path, os.X_OK) else ""


def vnr_or_exit(program):
    """For scripts: the vnr binary, else exits with why the harness cannot run here."""
    why, vnr = missing_tools(), find_vnr()
    if why or not vnr:
        sys.exit(f"{program}: {why or 'no vnr binary (build first or set VNR_CLI)'}")
    return vnr


def run_vnr(vnr, *args, timeout=300):
    """Runs vnr and returns its CompletedProcess; raises with its stderr when it fails."""
    proc = subprocess.run([vnr, *map(str, args)], capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"vnr {' '.join(map(str, args))} failed ({proc.returncode}): {proc.stderr.strip()}")
    return proc


class ViewServer:
    """`vnr view ARGS --port 0` as a subprocess; url is the printed URL (with the token)."""

    def __init__(self, vnr, *args, timeout=60):
        self.proc = subprocess.Popen([vnr, "view", *map(str, args), "--port", "0"], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.stderr_lines = []
        threading.Thread(target=self._drain_stderr, daemon=True).start()
        line = self._read_url_line(timeout)
        prefix = "vnr view: "
        if not line.startswith(prefix):
            self.proc.kill()
            raise RuntimeError(f"vnr view printed {line!r}; stderr: {''.join(self.stderr_lines)}")
        self.url = line[len(prefix):].strip()
        parts = urllib.parse.urlsplit(self.url)
        self.origin = f"{parts.scheme}://{parts.netloc}"
        self.token = urllib.parse.parse_qs(parts.query)["token"][0]

    def _read_url_line(self, timeout):
        result = []
        reader = threading.Thread(target=lambda: result.append(self.proc.stdout.readline()), daemon=True)
        reader.start()
        reader.join(timeout)
        return result[0] if result else ""

    def _drain_stderr(self):
        for line in self.proc.stderr:
            self.stderr_lines.append(line)

    def get(self, path, token=True):
        """(status, body bytes) of an HTTP GET; token=False sends none, a string sends that one."""
        if token is True:
            token = self.token
        url = self.origin + path + (f"?token={token}" if token else "")
        try:
            with urllib.request.urlopen(url, timeout=30) as r:
                return r.status, r.read()
        except urllib.error.HTTPError as e:
            return e.code, e.read()

    def fetch(self, path, dest):
        status, body = self.get(path)
        if status != 200:
            raise RuntimeError(f"GET {path}: HTTP {status} {body[:200]!r}")
        with open(dest, "wb") as f:
            f.write(body)
        return dest

    def terminate(self, timeout=5):
        """SIGTERM; (exit code or None when it did not exit in time, seconds taken)."""
        if self.proc.poll() is not None:
            return self.proc.returncode, 0.0
        start = time.monotonic()
        self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            return None, time.monotonic() - start
        time.sleep(0.1)  # let the stderr reader take the last lines
        return code, time.monotonic() - start


class Browser:
    """Headless Chromium (fresh profile, 1200x900 window) driven by Selenium."""

    def __init__(self):
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
        self.profile = tempfile.mkdtemp(prefix="vnr-chromium-")
        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                    "--disable-background-networking", "--disable-component-update", "--disable-sync",
                    f"--user-data-dir={self.profile}", "--window-size=1200,900"):
            options.add_argument(arg)
        self.driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
        self.driver.set_window_size(1200, 900)

    def js(self, script, *args):
        return self.driver.execute_script(script, *args)

    def wait(self, condition, timeout=30, what=None, poll=0.05):
        """Polls the JS expression `condition` (a `return` is prepended) until it is truthy; its value."""
        deadline = time.monotonic() + timeout
        while True:
            value = self.js("try { return " + condition + "; } catch (e) { return null; }")
            if value:
                return value
            if time.monotonic() > deadline:
                raise TimeoutError(f"waited {timeout}s for {what or condition}")
            time.sleep(poll)

    def open_viewer(self, url, timeout=30):
        self.driver.get(url)
        self.wait("window.vnrViewer && vnrViewer.connected && vnrViewer.state !== null", timeout, "hello")

    def wait_settled(self, timeout=60):
        """Waits until the newest network frame has the newest state's settings, full resolution and
        the whole accumulation (the engine is idle); returns that frame's header."""
        return self.wait(
            "(() => { const s = vnrViewer.state, h = vnrViewer.lastHeader.network;"
            " const max = s.render.max_frames || {raymarch: 8, shadow: 16, pathtrace: 256}[s.render.mode];"
            " return h && h.version >= s.version && h.refined && h.accumulated >= max"
            " && h.width === s.viewport.width && h.height === s.viewport.height ? h : null; })()",
            timeout, "a settled network frame")

    def canvas_png(self, element_id, dest):
        """The canvas's pixels as a PNG file."""
        import base64
        data = self.js(f"return document.getElementById('{element_id}').toDataURL('image/png');")
        with open(dest, "wb") as f:
            f.write(base64.b64decode(data.split(",", 1)[1]))
        return dest

    def quit(self):
        try:
            self.driver.quit()
        finally:
            shutil.rmtree(self.profile, ignore_errors=True)


def render_args_of(state):
    """`vnr render` flags for a viewer state's render settings (camera and TF come from scene.json).
    The page's `auto` on the CPU is the brick cache whatever the frame count (`vnr render`'s takes it from 8
    frames): `cache`."""
    r = state["render"]
    strategy = "cache" if r["strategy"] == "auto" else r["strategy"]
    args = ["--mode", r["mode"], "--strategy", strategy, "--macrocells", r["macrocells"],
            "--step", repr(r["step"]), "--light", ",".join(repr(v) for v in r["light"]),
            "--density", repr(r["density"])]
    return args + (["--shade"] if r["shade"] else [])


def render_psnr(vnr, input_path, scene, width, height, spp, reference, work_dir, extra=()):
    """Renders input with scene.json at WxH and spp frames, compared with reference: its image PSNR (dB)."""
    out = os.path.join(work_dir, "render.png")
    report = os.path.join(work_dir, "render_report.json")
    run_vnr(vnr, "render", input_path, "--scene", scene, "--size", f"{width}x{height}", "--spp", spp,
            "--reference", reference, "--report", report, "-o", out, "-q", *extra)
    with open(report) as f:
        return json.load(f)["image_psnr"]


def log(msg):
    print(msg, file=sys.stderr, flush=True)
