"""The README's picture of the viewer: `vnr view VOLUME` in headless Chromium, training started from the
page, the whole page captured SECONDS after Start.

  /usr/bin/python3 scripts/viewer_screenshot.py VOLUME OUT.png [--seconds 60] [--size 1400x1160]

VNR_CLI names the vnr binary (default build/vnr). Needs what the browser tests need (scripts/setup.sh).
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "tests", "browser"))
import harness  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("volume")
    parser.add_argument("out")
    parser.add_argument("--seconds", type=float, default=60.0, help="training time before the capture")
    parser.add_argument("--size", default="1400x1160", help="browser window WxH")
    args = parser.parse_args()
    vnr = harness.vnr_or_exit("viewer_screenshot")
    width, height = (int(v) for v in args.size.split("x"))
    with tempfile.TemporaryDirectory() as work:
        server = harness.ViewServer(vnr, args.volume, "--save-dir", work)
        try:
            browser = harness.Browser()
            try:
                browser.driver.set_window_size(width, height)
                browser.open_viewer(server.url)
                browser.driver.find_element("id", "train-start").click()
                browser.wait("vnrViewer.state.training.state === 'running'", 30, "training to run")
                time.sleep(args.seconds)
                tmp = os.path.join(os.path.dirname(os.path.abspath(args.out)), ".tmp-" + os.path.basename(args.out))
                browser.driver.save_screenshot(tmp)
                os.replace(tmp, args.out)  # atomic: a reader never sees half a PNG
            finally:
                browser.quit()
        finally:
            server.terminate()
    print(f"viewer_screenshot: wrote {args.out}")


if __name__ == "__main__":
    main()
