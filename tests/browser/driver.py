"""Drives headless Chromium through the DevTools protocol to check the splat viewer.

For each held-out camera it opens the viewer at that camera (the `view=` URL parameter), waits
until the camera's depth sort has been drawn, takes a screenshot of the canvas and compares it
with the CPU rasteriser's render of the same model from the same camera (`transcode render`).
Every view must reach the PSNR floor; the pages must log no console error, exception or
failed load. It then breaks the viewer on purpose (a wrong sort, wrong shader maths), serving
the broken script through the protocol's request interception, and checks that each break
fails the comparison: a check that passes a broken viewer checks nothing.

Usage: driver.py --chromium BIN --url BASE_URL --file-url FILE_URL --cpu DIR --views a,b,...
Prints one line per check and a closing 'N passed, N failed' line; exits non-zero on a failure.
"""

import argparse
import base64
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request

import numpy as np
import websocket
from PIL import Image

# The issue asks for 30 dB; the viewer matches the CPU rasteriser to about 60 dB, and 40 dB
# leaves room for other GPUs and drivers while catching subtler breaks (see MUTATIONS).
PSNR_FLOOR_DB = 40.0

# Deliberate breaks of viewer.js: (name, text in the bundle, replacement). Each must make at
# least one view fall below the floor.
MUTATIONS = [
    (
        "sort front to back instead of back to front",
        "out[m - 1 - countHigh[k >>> 16]++] = order2[j];",
        "out[countHigh[k >>> 16]++] = order2[j];",
    ),
    (
        "conic with the wrong sign of its off-diagonal term",
        "v_conic = vec3(c / det, -b / det, a / det);",
        "v_conic = vec3(c / det, b / det, a / det);",
    ),
    (
        "camera frame with y up instead of COLMAP's y down",
        "1.0 - 2.0 * pixel.y / u_size.y",
        "2.0 * pixel.y / u_size.y - 1.0",
    ),
    (
        "SH degree-1 band with Inria's signs dropped",
        "vec3 c = -SH_C1 * y * s[0].xyz + SH_C1 * z * vec3(s[0].w, s[1].xy)\\n        - SH_C1 * x",
        "vec3 c = SH_C1 * y * s[0].xyz - SH_C1 * z * vec3(s[0].w, s[1].xy)\\n        + SH_C1 * x",
    ),
]


class Browser:
    """One headless Chromium with one page, spoken to over the DevTools protocol."""

    def __init__(self, binary):
        self.profile = tempfile.mkdtemp(prefix="viewer-chromium-")
        args = [
            binary,
            "--headless=new",
            "--no-sandbox",  # CI runs as root, where Chromium's sandbox cannot start
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",  # software WebGL: the CI machine has no GPU
            "--remote-debugging-port=0",
            f"--user-data-dir={self.profile}",
            "--no-first-run",
            "--disable-extensions",
            "--window-size=1280,1024",
            "about:blank",
        ]
        self.proc = subprocess.Popen(args, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
        endpoint = None
        deadline = time.time() + 60
        while time.time() < deadline:
            line = self.proc.stderr.readline()
            if not line:
                if self.proc.poll() is not None:
                    break
                continue
            m = re.search(r"DevTools listening on (ws://\S+)", line)
            if m:
                endpoint = m.group(1)
                break
        if endpoint is None:
            raise RuntimeError(f"Chromium did not start (exit {self.proc.poll()})")
        port = re.search(r":(\d+)/", endpoint).group(1)
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list") as r:
            pages = [t for t in json.load(r) if t["type"] == "page"]
        self.ws = websocket.create_connection(
            pages[0]["webSocketDebuggerUrl"], timeout=120, suppress_origin=True
        )
        self.next_id = 0
        self.events = []
        self.errors = []
        self.mutation = None
        for domain in ("Page", "Runtime", "Log"):
            self.call(f"{domain}.enable")
        self.call(
            "Emulation.setDeviceMetricsOverride",
            width=1280,
            height=1024,
            deviceScaleFactor=1,
            mobile=False,
        )

    def close(self):
        try:
            self.ws.close()
        finally:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
            shutil.rmtree(self.profile, ignore_errors=True)

    def call(self, method, **params):
        self.next_id += 1
        mine = self.next_id
        self.ws.send(json.dumps({"id": mine, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == mine:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.handle(msg)

    def handle(self, msg):
        method = msg.get("method")
        p = msg.get("params", {})
        if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            text = " ".join(str(a.get("value", a.get("description", ""))) for a in p["args"])
            self.errors.append(f"console.{p['type']}: {text}")
        elif method == "Runtime.exceptionThrown":
            d = p["exceptionDetails"]
            self.errors.append(f"exception: {d.get('exception', {}).get('description', d.get('text'))}")
        elif method == "Log.entryAdded" and p["entry"]["level"] == "error":
            self.errors.append(f"log: {p['entry']['text']} {p['entry'].get('url', '')}")
        elif method == "Fetch.requestPaused":
            self.fulfil_mutated(p)

    def evaluate(self, expression, await_promise=False):
        r = self.call(
            "Runtime.evaluate",
            expression=expression,
            returnByValue=True,
            awaitPromise=await_promise,
        )
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expression}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def pump(self, seconds):
        """Reads events for a while (console messages, intercepted requests)."""
        self.ws.settimeout(seconds)
        try:
            while True:
                self.handle(json.loads(self.ws.recv()))
        except websocket.WebSocketTimeoutException:
            pass
        finally:
            self.ws.settimeout(120)

    def open(self, url, timeout=120):
        """Opens `url` and waits until the viewer has drawn its camera's sort; returns its state."""
        self.call("Page.navigate", url=url)
        deadline = time.time() + timeout
        while time.time() < deadline:
            self.pump(0.2)
            state = self.evaluate(
                "window.splatViewer ? JSON.stringify(window.splatViewer) : null"
            )
            if state:
                s = json.loads(state)
                if s.get("error"):
                    raise RuntimeError(f"the viewer failed: {s['error']}")
                if s.get("ready"):
                    # Two more frames, so the drawn frame is the one on screen.
                    self.evaluate(
                        "new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))",
                        await_promise=True,
                    )
                    return s
        raise RuntimeError(f"{url}: the viewer was not ready within {timeout} s")

    def canvas_screenshot(self):
        rect = json.loads(
            self.evaluate(
                "JSON.stringify(document.querySelector('.sv-canvas').getBoundingClientRect())"
            )
        )
        scroll = json.loads(self.evaluate("JSON.stringify([window.scrollX, window.scrollY])"))
        shot = self.call(
            "Page.captureScreenshot",
            format="png",
            captureBeyondViewport=True,
            clip={
                "x": rect["x"] + scroll[0],
                "y": rect["y"] + scroll[1],
                "width": rect["width"],
                "height": rect["height"],
                "scale": 1,
            },
        )
        img = Image.open(io.BytesIO(base64.b64decode(shot["data"]))).convert("RGB")
        return np.asarray(img, dtype=np.float64) / 255.0

    def set_mutation(self, mutation):
        """Serves viewer.js with `mutation` applied (None: as it is)."""
        self.mutation = mutation
        if mutation:
            self.call(
                "Fetch.enable",
                patterns=[{"urlPattern": "*viewer.js*", "requestStage": "Response"}],
            )
        else:
            self.call("Fetch.disable")

    def fulfil_mutated(self, p):
        body = self.call("Fetch.getResponseBody", requestId=p["requestId"])
        text = base64.b64decode(body["body"]).decode() if body["base64Encoded"] else body["body"]
        _, old, new = self.mutation
        if old not in text:
            raise RuntimeError(f"mutation text not in viewer.js: {old}")
        text = text.replace(old, new)
        self.call(
            "Fetch.fulfillRequest",
            requestId=p["requestId"],
            responseCode=200,
            responseHeaders=[{"name": "Content-Type", "value": "text/javascript"}],
            body=base64.b64encode(text.encode()).decode(),
        )


def psnr(a, b):
    mse = float(np.mean((a - b) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)


def cpu_render(cpu_dir, view):
    return np.asarray(Image.open(os.path.join(cpu_dir, f"{view}.png")).convert("RGB"), dtype=np.float64) / 255.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--chromium", required=True)
    ap.add_argument("--url", required=True, help="the viewer page over HTTP (transcode view)")
    ap.add_argument("--file-url", required=True, help="report.html opened from disk")
    ap.add_argument("--cpu", required=True, help="folder of the CPU renders, VIEW.png")
    ap.add_argument("--views", required=True)
    ap.add_argument("--shots", help="folder to keep the screenshots in")
    ap.add_argument("--bench", type=int, default=0, help="frames of a frame-rate measurement")
    args = ap.parse_args()
    views = args.views.split(",")
    passed, failed = 0, 0

    def check(ok, line):
        nonlocal passed, failed
        print(("ok    " if ok else "FAIL  ") + line, flush=True)
        if ok:
            passed += 1
        else:
            failed += 1

    # A timeout's SIGTERM unwinds through `finally`, so Chromium is not left behind.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    browser = Browser(args.chromium)
    try:
        info = browser.evaluate(
            "(() => { const c = document.createElement('canvas').getContext('webgl2');"
            " if (!c) return 'no WebGL2';"
            " const d = c.getExtension('WEBGL_debug_renderer_info');"
            " return d ? c.getParameter(d.UNMASKED_RENDERER_WEBGL) : c.getParameter(c.RENDERER); })()"
        )
        print(f"WebGL2 renderer: {info}", flush=True)
        if info == "no WebGL2":
            check(False, "Chromium offers WebGL2")
        worst = float("inf")
        for view in views:
            state = browser.open(f"{args.url}?view={view}")
            shot = browser.canvas_screenshot()
            ref = cpu_render(args.cpu, view)
            if shot.shape != ref.shape:
                check(False, f"{view}: screenshot {shot.shape} but CPU render {ref.shape}")
                continue
            value = psnr(shot, ref)
            worst = min(worst, value)
            sort_ms = state["sortMs"][-1] if state["sortMs"] else float("nan")
            check(
                value >= PSNR_FLOOR_DB,
                f"{view}: browser vs CPU render {value:.2f} dB (floor {PSNR_FLOOR_DB}), "
                f"{state['splats']} splats, sort {sort_ms:.1f} ms",
            )
            if args.shots:
                Image.fromarray((shot * 255).round().astype(np.uint8)).save(
                    os.path.join(args.shots, f"{view}.png")
                )
        print(f"worst view: {worst:.2f} dB", flush=True)

        # report.html opened from disk: the model comes from the embedded script.
        state = browser.open(f"{args.file_url}?view={views[0]}")
        value = psnr(browser.canvas_screenshot(), cpu_render(args.cpu, views[0]))
        status = browser.evaluate("document.querySelector('.sv-status').textContent")
        check(
            value >= PSNR_FLOOR_DB and "(worker)" in status,
            f"report.html from disk, {views[0]}: {value:.2f} dB; {status}",
        )

        if args.bench:
            # The camera moves every frame, so there is no "ready": wait for the result.
            browser.call("Page.navigate", url=f"{args.url}?view={views[0]}&bench={args.bench}")
            bench = None
            deadline = time.time() + 300
            while bench is None and time.time() < deadline:
                browser.pump(0.5)
                bench = json.loads(browser.evaluate("JSON.stringify(window.splatViewer.bench)"))
            check(bench is not None, f"frame rate while orbiting: {json.dumps(bench)}")

        check(not browser.errors, "no console errors, exceptions or failed loads")
        for e in browser.errors:
            print(f"      {e}")

        # Each deliberate break must fail the comparison on some view.
        for mutation in MUTATIONS:
            browser.set_mutation(mutation)
            values = []
            for view in views[:4]:
                browser.errors.clear()
                try:
                    browser.open(f"{args.url}?view={view}", timeout=60)
                    values.append(psnr(browser.canvas_screenshot(), cpu_render(args.cpu, view)))
                except RuntimeError as e:
                    values.append(float("-inf"))
                    print(f"      ({view}: {e})")
            browser.set_mutation(None)
            low = min(values)
            check(
                low < PSNR_FLOOR_DB,
                f"broken viewer caught ({mutation[0]}): worst view {low:.2f} dB",
            )
    finally:
        browser.close()
    print(f"{passed} passed, {failed} failed", flush=True)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
