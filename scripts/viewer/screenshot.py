#!/usr/bin/env python3
"""Opens a run's view.html in headless Chromium (software WebGL: ANGLE on
SwiftShader), waits until the page reports the model drawn, screenshots it
at preview_0.png's size and compares the two (examples/compare_images.rs).

    python3 scripts/viewer/screenshot.py RUN_DIR [OUT_DIR]

RUN_DIR: a run's output folder with view.html and preview_0.png.
OUT_DIR (default /tmp/surfsynth-view-NAME, NAME = RUN_DIR's name) receives
  view.png          the initial view, caption hidden, compared with preview_0.png
  view_caption.png  the same with the page's caption
  compare.png       preview_0.png | view.png | their difference x3
                    (red: only the preview has the object there; blue: only the page)
  compare.json      silhouette IoU, mean absolute difference, bounds, ...
  chromium.log      the browser's messages
Exits 1 when the page does not report the model drawn within TIMEOUT seconds
(environment, default 180), or shows an error. Needs /usr/bin/chromium
(Debian: apt-get install chromium; CHROMIUM overrides, CHROMIUM_FLAGS adds
flags, e.g. --disable-3d-apis to see the page without WebGL) and cargo for the
comparison (or COMPARE=path/to/compare_images; COMPARE=none skips it).

Only Python's standard library: the browser is driven over the DevTools
protocol on a pipe (--remote-debugging-pipe, no port), which lets the script
wait for the page's own signal (body data-state="shown" and title "ready",
set after the first frame with the model) instead of guessing a delay.
"""

import base64
import fcntl
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def png_size(path):
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] != b"\x89PNG\r\n\x1a\n":
        sys.exit(f"{path} is not a PNG")
    return struct.unpack(">II", head[16:24])


class Browser:
    """Chromium with the DevTools protocol on fds 3 (commands in) and 4
    (replies out), messages separated by NUL."""

    def __init__(self, chromium, profile, log):
        to_child, self._w = os.pipe()
        self._r, from_child = os.pipe()
        # Above 9, so that placing them on 3 and 4 clobbers neither.
        to_child, from_child = (self._high(fd) for fd in (to_child, from_child))
        args = [
            "--headless",
            "--no-sandbox",
            "--use-gl=angle",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--ignore-gpu-blocklist",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-default-apps",
            "--disable-extensions",
            "--no-first-run",
            "--no-default-browser-check",
            "--hide-scrollbars",
            "--mute-audio",
            "--force-device-scale-factor=1",
            f"--user-data-dir={profile}",
            "--remote-debugging-pipe",
            *os.environ.get("CHROMIUM_FLAGS", "").split(),
            "about:blank",
        ]
        shell = f'exec "$0" "$@" 3<&{to_child} 4>&{from_child} {to_child}<&- {from_child}>&-'
        self.proc = subprocess.Popen(
            ["bash", "-c", shell, chromium, *args],
            pass_fds=(to_child, from_child),
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=log,
        )
        os.close(to_child)
        os.close(from_child)
        self._buf = b""
        self._id = 0
        self.session = None

    @staticmethod
    def _high(fd):
        high = fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
        os.close(fd)
        return high

    def _read_message(self, deadline):
        while b"\0" not in self._buf:
            if time.time() > deadline:
                raise TimeoutError("no reply from Chromium")
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed the DevTools pipe (see chromium.log)")
            self._buf += chunk
        message, self._buf = self._buf.split(b"\0", 1)
        return json.loads(message)

    def call(self, method, params=None, session=True, timeout=120):
        self._id += 1
        message = {"id": self._id, "method": method, "params": params or {}}
        if session and self.session:
            message["sessionId"] = self.session
        os.write(self._w, json.dumps(message).encode() + b"\0")
        deadline = time.time() + timeout
        while True:
            reply = self._read_message(deadline)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def evaluate(self, expression):
        result = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True})
        return result.get("result", {}).get("value")

    def screenshot(self, path):
        data = self.call("Page.captureScreenshot", {"format": "png"})["data"]
        with open(path, "wb") as f:
            f.write(base64.b64decode(data))

    def close(self):
        try:
            self.call("Browser.close", session=False, timeout=10)
        except Exception:
            pass
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


STATE = """(function () {
  var b = document.body, m = document.getElementById("message");
  return { state: b ? b.dataset.state : null, title: document.title,
           message: m && m.style.display === "block" ? m.textContent : "" };
})()"""

GL_RENDERER = """(function () {
  var gl = document.createElement("canvas").getContext("webgl2") ||
           document.createElement("canvas").getContext("webgl");
  if (!gl) return "no WebGL";
  var e = gl.getExtension("WEBGL_debug_renderer_info");
  return e ? gl.getParameter(e.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
})()"""


def main():
    if len(sys.argv) < 2 or not os.path.isdir(sys.argv[1]):
        print(__doc__.split("\n\n")[1])
        sys.exit(2)
    run_dir = os.path.abspath(sys.argv[1])
    name = os.path.basename(run_dir.rstrip("/"))
    out = os.path.abspath(sys.argv[2] if len(sys.argv) > 2 else f"/tmp/surfsynth-view-{name}")
    os.makedirs(out, exist_ok=True)
    chromium = os.environ.get("CHROMIUM", "/usr/bin/chromium")
    timeout = float(os.environ.get("TIMEOUT", "180"))
    for f in ("view.html", "preview_0.png"):
        if not os.path.isfile(os.path.join(run_dir, f)):
            sys.exit(f"no {f} in {run_dir}")
    if not shutil.which(chromium):
        sys.exit(f"no Chromium at {chromium} (apt-get install chromium)")
    width, height = png_size(os.path.join(run_dir, "preview_0.png"))

    profile = tempfile.mkdtemp(prefix="surfsynth-chromium-")
    ok = False
    with open(os.path.join(out, "chromium.log"), "wb") as log:
        browser = Browser(chromium, profile, log)
        try:
            target = browser.call("Target.createTarget", {"url": "about:blank"}, session=False)
            attached = browser.call(
                "Target.attachToTarget", {"targetId": target["targetId"], "flatten": True}, session=False
            )
            browser.session = attached["sessionId"]
            browser.call(
                "Emulation.setDeviceMetricsOverride",
                {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
            )
            browser.call("Page.enable")
            started = time.time()
            browser.call("Page.navigate", {"url": f"file://{run_dir}/view.html#bare"})
            while True:
                state = browser.evaluate(STATE) or {}
                if state.get("state") == "shown" and state.get("title") == "ready":
                    ok = True
                    break
                if state.get("state") == "error" or time.time() - started > timeout:
                    break
                time.sleep(0.25)
            seconds = time.time() - started
            renderer = browser.evaluate(GL_RENDERER)
            print(f"page: {state} after {seconds:.1f} s, {width}x{height}, WebGL: {renderer}")
            browser.screenshot(os.path.join(out, "view.png"))
            browser.evaluate('document.body.classList.remove("hide-caption")')
            time.sleep(0.5)
            browser.screenshot(os.path.join(out, "view_caption.png"))
        finally:
            browser.close()
            shutil.rmtree(profile, ignore_errors=True)
    if not ok:
        print("the page did not report the model drawn", file=sys.stderr)

    compare = os.environ.get("COMPARE")
    args = [os.path.join(run_dir, "preview_0.png"), os.path.join(out, "view.png"), os.path.join(out, "compare.png")]
    if compare != "none":
        if compare:
            cmd = [compare, *args]
        else:
            cmd = ["nice", "cargo", "run", "--quiet", "--release", "--example", "compare_images", "--", *args]
        result = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
        if result.returncode != 0:
            sys.exit(f"compare_images failed: {result.stderr}")
        with open(os.path.join(out, "compare.json"), "w") as f:
            f.write(result.stdout)
        print(result.stdout.strip())
        print(f"look at: {args[2]} (preview_0.png | view.png | difference)")
    print(f"screenshots: {args[1]}, {os.path.join(out, 'view_caption.png')}")
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
