#!/usr/bin/env python3
"""Opens a mogen viewer page (motion-core/src/export/viewer.rs) from disk in headless Chromium
and checks that it works: no console errors or uncaught exceptions, WebGL running, a 3-D view
that is not blank, an animation that moves, and (`--rigs N`) N samples on a user's rig played
from their skinned GLBs.

    python3 tests/browser/check_viewer.py path/to/viewer.html [--screenshot out.png] [--rigs N]

Needs only Python 3 (standard library) and a Chromium: `chromium-headless-shell`, `chromium`
or `google-chrome` on PATH, or --chromium PATH. It drives the browser through the DevTools
protocol over a pipe (`--remote-debugging-pipe`: JSON messages ending in NUL on fds 3 and 4),
and WebGL runs in software (SwiftShader), so no GPU or display is needed. Exits 0 when every
check passes, 1 with the failures listed otherwise, 2 when the browser cannot be run.
"""

import argparse
import base64
import fcntl
import json
import os
import pathlib
import select
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import zlib

VIEWPORT = (1280, 800)
# Seconds after the load event before the first screenshot, and between the two.
SETTLE_S = 2.0
GAP_S = 1.0
# A drawn scene has far more colours than this (shading, antialiasing); a blank canvas has one.
MIN_COLOURS = 200
# The commonest colour (the background) may cover at most this fraction of the view.
MAX_COMMONEST = 0.97
# At least this many pixels of the view must change between the screenshots.
MIN_CHANGED_PX = 500
TIMEOUT_S = 60.0

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--hide-scrollbars",
    "--mute-audio",
    f"--window-size={VIEWPORT[0]},{VIEWPORT[1]}",
    "--remote-debugging-pipe",
]


class BrowserError(Exception):
    """The browser could not be started or stopped answering."""


class DevTools:
    """A DevTools-protocol connection over Chromium's debugging pipe."""

    def __init__(self, chromium, user_data_dir, log):
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()
        # Chromium reads commands on fd 3 and writes replies and events on fd 4. The child's ends
        # are first moved above 9 so that placing them on 3 and 4 cannot overwrite each other.
        child_r = fcntl.fcntl(to_browser_r, fcntl.F_DUPFD_CLOEXEC, 10)
        child_w = fcntl.fcntl(from_browser_w, fcntl.F_DUPFD_CLOEXEC, 10)
        for fd in (to_browser_r, from_browser_w):
            os.close(fd)

        def place_pipe_ends():
            # dup2 leaves the copies inheritable; every other descriptor is close-on-exec.
            os.dup2(child_r, 3)
            os.dup2(child_w, 4)

        command = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={user_data_dir}", "about:blank"]
        self.process = subprocess.Popen(
            command, stdin=subprocess.DEVNULL, stdout=log, stderr=log, close_fds=False, preexec_fn=place_pipe_ends
        )
        os.close(child_r)
        os.close(child_w)
        self._buffer = b""
        self._next_id = 0
        self.events = []

    def _read_message(self, deadline):
        """The next message, or None when `deadline` (time.monotonic()) passes first."""
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            ready, _, _ = select.select([self._from_browser], [], [], left)
            if ready:
                chunk = os.read(self._from_browser, 1 << 20)
                if not chunk:
                    raise BrowserError(f"the browser closed the pipe (exit status {self.process.poll()})")
                self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def _expect_message(self, deadline, what):
        message = self._read_message(deadline)
        if message is None:
            raise BrowserError(f"the browser did not answer in time ({what})")
        return message

    def call(self, method, params=None, session=None, timeout_s=30.0):
        """Sends a command and returns its result; events that arrive meanwhile are kept."""
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout_s
        while True:
            reply = self._expect_message(deadline, method)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self.events.append(reply)

    def pump(self, seconds):
        """Collects events for `seconds`."""
        deadline = time.monotonic() + seconds
        while (event := self._read_message(deadline)) is not None:
            self.events.append(event)

    def wait_for(self, method, timeout_s):
        """Collects events until one named `method` arrives."""
        deadline = time.monotonic() + timeout_s
        while not any(e.get("method") == method for e in self.events):
            self.events.append(self._expect_message(deadline, method))

    def close(self):
        try:
            self.call("Browser.close", timeout_s=5.0)
        except (BrowserError, OSError):
            pass
        try:
            self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        os.close(self._to_browser)
        os.close(self._from_browser)


def decode_png(data):
    """(width, height, rows of RGB(A) bytes) of an 8-bit, non-interlaced RGB or RGBA PNG."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG")
    pos, idat = 8, []
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos : pos + 8])
        body = data[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        pos += 12 + length
    if depth != 8 or colour not in (2, 6) or interlace:
        raise ValueError(f"unsupported PNG (depth {depth}, colour type {colour}, interlace {interlace})")
    bpp = 3 if colour == 2 else 4
    raw = zlib.decompress(b"".join(idat))
    stride = width * bpp
    rows, previous = [], bytearray(stride)
    for y in range(height):
        start = y * (stride + 1)
        kind, row = raw[start], bytearray(raw[start + 1 : start + 1 + stride])
        if kind == 1:
            for i in range(bpp, stride):
                row[i] = (row[i] + row[i - bpp]) & 0xFF
        elif kind == 2:
            row = bytearray((a + b) & 0xFF for a, b in zip(row, previous))
        elif kind == 3:
            for i in range(stride):
                left = row[i - bpp] if i >= bpp else 0
                row[i] = (row[i] + ((left + previous[i]) >> 1)) & 0xFF
        elif kind == 4:
            for i in range(stride):
                a = row[i - bpp] if i >= bpp else 0
                b = previous[i]
                c = previous[i - bpp] if i >= bpp else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                row[i] = (row[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 0xFF
        rows.append(bytes(row))
        previous = row
    return width, height, bpp, rows


def view_pixels(png, masks):
    """The RGB pixels of a screenshot outside the `masks` rectangles (the page's panels)."""
    width, height, bpp, rows = decode_png(png)
    pixels = []
    for y in range(height):
        row = rows[y]
        covered = [(int(l), int(r) + 1) for l, t, r, b in masks if t <= y <= b]
        for x in range(width):
            if any(l <= x < r for l, r in covered):
                continue
            i = x * bpp
            pixels.append(row[i : i + 3])
    return pixels


# Evaluated in the page: where its panels are, whether WebGL runs, what the readout says.
PAGE_STATE = """JSON.stringify((() => {
  const canvas = document.querySelector('#stage canvas');
  const gl = canvas && (canvas.getContext('webgl2') || canvas.getContext('webgl'));
  const info = gl && gl.getExtension('WEBGL_debug_renderer_info');
  const error = document.getElementById('error');
  return {
    panels: [...document.querySelectorAll('.panel')].map((e) => {
      const r = e.getBoundingClientRect();
      return [r.left, r.top, r.right, r.bottom];
    }),
    canvas: canvas ? [canvas.clientWidth, canvas.clientHeight] : null,
    webgl: gl ? (info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER)) : null,
    error: error && getComputedStyle(error).display !== 'none' ? error.textContent : null,
    readout: (document.getElementById('readout') || {}).textContent || null,
    reportRows: document.querySelectorAll('#report tr').length,
    rigs: window.mogenRigsShown === undefined ? null : window.mogenRigsShown,
  };
})())"""


def page_state(devtools, session):
    return json.loads(evaluate(devtools, session, PAGE_STATE))


def evaluate(devtools, session, expression):
    result = devtools.call("Runtime.evaluate", {"expression": expression, "returnByValue": True}, session)
    if "exceptionDetails" in result:
        raise BrowserError(f"evaluating {expression!r} failed: {result['exceptionDetails']}")
    return result["result"].get("value")


# Drives the page's controls: pause, scrub to the first frame, every sample and "all", 0.25x.
PAUSE = "document.getElementById('play').click(); document.getElementById('play').textContent"
SCRUB_TO_START = """(() => {
  const scrub = document.getElementById('scrub');
  scrub.value = '0';
  scrub.dispatchEvent(new Event('input'));
  return scrub.max;
})()"""
READOUT = "document.getElementById('readout').textContent"
SHOW_EACH_SAMPLE = """(() => {
  const select = document.getElementById('sample');
  const values = [...select.options].map((o) => o.value);
  for (const value of values) {
    select.value = value;
    select.dispatchEvent(new Event('change'));
  }
  const speed = document.getElementById('speed');
  speed.value = '0.25';
  speed.dispatchEvent(new Event('change'));
  return values;
})()"""


def exercise_controls(devtools, session, facts):
    """Failures of the playback controls; every sample is shown once on the way."""
    failures = []
    if evaluate(devtools, session, PAUSE) != "Play":
        failures.append("the play/pause button does not pause")
    devtools.pump(0.3)
    paused = evaluate(devtools, session, READOUT)
    devtools.pump(0.5)
    if evaluate(devtools, session, READOUT) != paused:
        failures.append("the frame readout moves while paused")
    facts["frames"] = int(evaluate(devtools, session, SCRUB_TO_START)) + 1
    devtools.pump(0.3)
    if not evaluate(devtools, session, READOUT).startswith("frame 0 "):
        failures.append("scrubbing to the start does not show frame 0")
    facts["sample switch"] = evaluate(devtools, session, SHOW_EACH_SAMPLE)
    devtools.pump(0.5)
    return failures


def screenshot(devtools, session):
    result = devtools.call("Page.captureScreenshot", {"format": "png"}, session)
    return base64.b64decode(result["data"])


def console_messages(events):
    """(errors, warnings) among the events: console errors and assertion failures, uncaught
    exceptions and the browser's error log entries; console and log warnings."""
    errors, warnings = [], []
    for event in events:
        method, params = event.get("method"), event.get("params", {})
        if method == "Runtime.consoleAPICalled":
            kind = params.get("type")
            words = " ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", []))
            if kind in ("error", "assert"):
                errors.append(f"console.{kind}: {words}")
            elif kind == "warning":
                warnings.append(words)
        elif method == "Runtime.exceptionThrown":
            details = params.get("exceptionDetails", {})
            errors.append(f"uncaught exception: {details.get('exception', {}).get('description') or details.get('text')}")
        elif method == "Log.entryAdded":
            entry = params.get("entry", {})
            if entry.get("level") == "error":
                errors.append(f"{entry.get('source')} error: {entry.get('text')} {entry.get('url', '')}".strip())
            elif entry.get("level") == "warning":
                warnings.append(entry.get("text", ""))
    return errors, warnings


def find_chromium(given):
    if given:
        return given
    for name in ("chromium-headless-shell", "chromium", "chromium-browser", "google-chrome", "chrome-headless-shell"):
        path = shutil.which(name)
        if path:
            return path
    return None


def check(page, chromium, screenshot_path, rigs):
    """Runs the checks (`rigs`: the samples on a user's rig the page must show); returns
    (failures, facts)."""
    failures, facts = [], {}
    with tempfile.TemporaryDirectory(prefix="mogen-viewer-check-") as scratch:
        log_path = pathlib.Path(scratch) / "chromium.log"
        with open(log_path, "wb") as log:
            devtools = DevTools(chromium, pathlib.Path(scratch) / "profile", log)
            try:
                target = devtools.call("Target.createTarget", {"url": "about:blank"})["targetId"]
                session = devtools.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
                for domain in ("Runtime", "Log", "Page"):
                    devtools.call(f"{domain}.enable", session=session)
                devtools.call(
                    "Emulation.setDeviceMetricsOverride",
                    {"width": VIEWPORT[0], "height": VIEWPORT[1], "deviceScaleFactor": 1, "mobile": False},
                    session,
                )
                navigated = devtools.call("Page.navigate", {"url": page.as_uri()}, session)
                if navigated.get("errorText"):
                    raise BrowserError(f"loading {page}: {navigated['errorText']}")
                devtools.wait_for("Page.loadEventFired", TIMEOUT_S)
                devtools.pump(SETTLE_S)
                first_state = page_state(devtools, session)
                first = screenshot(devtools, session)
                devtools.pump(GAP_S)
                second_state = page_state(devtools, session)
                second = screenshot(devtools, session)
                failures += exercise_controls(devtools, session, facts)
            except BrowserError as e:
                devtools.close()
                log.flush()
                tail = log_path.read_text(errors="replace")[-3000:]
                raise BrowserError(f"{e}\n--- browser log (tail) ---\n{tail}") from e
            devtools.close()
        events = devtools.events

    if screenshot_path:
        pathlib.Path(screenshot_path).write_bytes(first)
    errors, facts["warnings"] = console_messages(events)
    failures += errors
    facts["webgl"] = first_state["webgl"]
    facts["readouts"] = [first_state["readout"], second_state["readout"]]
    facts["report rows"] = first_state["reportRows"]
    facts["rigs shown"] = first_state["rigs"]
    if first_state["rigs"] != rigs:
        failures.append(f"the page shows {first_state['rigs']} samples on a rig, expected {rigs}")
    if first_state["error"]:
        failures.append(f"the page shows an error: {first_state['error']}")
    if not first_state["canvas"]:
        failures.append("the page has no canvas")
    if not first_state["webgl"]:
        failures.append("no WebGL context on the canvas")
    if first_state["readout"] == second_state["readout"]:
        failures.append(f"the frame readout did not change in {GAP_S} s: {first_state['readout']!r}")

    panels = first_state["panels"]
    a, b = view_pixels(first, panels), view_pixels(second, panels)
    counts = {}
    for p in a:
        counts[p] = counts.get(p, 0) + 1
    commonest = max(counts.values()) / max(len(a), 1)
    changed = sum(1 for p, q in zip(a, b) if p != q)
    facts["view pixels"] = len(a)
    facts["distinct colours"] = len(counts)
    facts["commonest colour share"] = round(commonest, 3)
    facts["pixels changed between screenshots"] = changed
    if len(counts) < MIN_COLOURS:
        failures.append(f"the 3-D view looks blank: {len(counts)} distinct colours (want at least {MIN_COLOURS})")
    if commonest > MAX_COMMONEST:
        failures.append(f"the 3-D view looks blank: one colour covers {commonest:.1%} of it")
    if changed < MIN_CHANGED_PX:
        failures.append(f"the animation does not play: {changed} pixels changed in {GAP_S} s (want {MIN_CHANGED_PX})")
    return failures, facts


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("page", type=pathlib.Path, help="the viewer page (.html)")
    parser.add_argument("--screenshot", help="write the first screenshot (PNG) here")
    parser.add_argument("--chromium", help="the browser binary (default: found on PATH)")
    parser.add_argument("--rigs", type=int, default=0,
                        help="how many samples on a user's rig (--rig) the page must play from their GLBs")
    args = parser.parse_args()

    page = args.page.resolve()
    if not page.is_file():
        print(f"FAIL: {args.page} is not a file", file=sys.stderr)
        return 2
    chromium = find_chromium(args.chromium)
    if not chromium:
        print("FAIL: no Chromium found (install chromium-headless-shell or pass --chromium)", file=sys.stderr)
        return 2
    try:
        failures, facts = check(page, chromium, args.screenshot, args.rigs)
    except (BrowserError, OSError, ValueError) as e:
        print(f"FAIL: could not run the browser check: {e}", file=sys.stderr)
        return 2
    print(f"viewer check of {page} in {chromium}")
    for key, value in facts.items():
        if key == "warnings":
            print(f"  console warnings: {len(value)}")
            for w in value[:5]:
                print(f"    {w[:200]}")
        else:
            print(f"  {key}: {value}")
    if args.screenshot:
        print(f"  screenshot: {args.screenshot}")
    if failures:
        print(f"FAIL: {len(failures)} problem(s):", file=sys.stderr)
        for f in failures:
            print(f"  - {f}", file=sys.stderr)
        return 1
    print("OK: no console errors, WebGL running, the view is drawn, the animation plays and the controls work")
    return 0


if __name__ == "__main__":
    sys.exit(main())
