"""Open an HTML page in a real headless Chromium and report what a user would see: a screenshot,
console errors, uncaught exceptions, failed or outgoing network requests.

Chromium (Debian packages ``chromium`` and ``chromium-driver``) is driven over the DevTools
protocol with the ``websocket-client`` package: the browser starts with ``--remote-debugging-port=0``
and a fresh ``--user-data-dir`` and writes the port it chose to ``DevToolsActivePort`` there;
``Runtime``, ``Log`` and ``Network`` events are collected while the page loads, then
``Page.captureScreenshot`` gives the PNG. Used by the tests of the HTML reports.
"""
from __future__ import annotations

import base64
import json
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["PageCheck", "check_page", "find_chromium"]

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-dev-shm-usage",
         "--no-default-browser-check", "--mute-audio", "--hide-scrollbars"]


def find_chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome"):
        p = shutil.which(name)
        if p:
            return p
    return None


@dataclass
class PageCheck:
    url: str
    screenshot: Path | None = None
    console_errors: list = field(default_factory=list)     # console.error / assert messages
    exceptions: list = field(default_factory=list)         # uncaught JS exceptions
    log_errors: list = field(default_factory=list)         # browser log entries of level error
    requests: list = field(default_factory=list)           # URLs requested other than the page and data:
    failed_requests: list = field(default_factory=list)
    title: str = ""
    body_text_length: int = 0
    images: int = 0
    broken_images: int = 0

    @property
    def ok(self) -> bool:
        return not (self.console_errors or self.exceptions or self.log_errors or self.failed_requests
                    or self.broken_images)

    def problems(self) -> list:
        return ([f"console: {m}" for m in self.console_errors] + [f"exception: {m}" for m in self.exceptions]
                + [f"log: {m}" for m in self.log_errors] + [f"request failed: {m}" for m in self.failed_requests]
                + ([f"{self.broken_images} image(s) did not decode"] if self.broken_images else []))


class _CDP:
    def __init__(self, ws_url, timeout):
        import websocket
        self.ws = websocket.create_connection(ws_url, timeout=timeout, suppress_origin=True)
        self.n = 0
        self.events = []

    def call(self, method, params=None, timeout=60.0):
        import websocket
        self.n += 1
        mid = self.n
        self.ws.send(json.dumps({"id": mid, "method": method, "params": params or {}}))
        end = time.time() + timeout
        self.ws.settimeout(1.0)
        while time.time() < end:
            try:
                msg = json.loads(self.ws.recv())
            except websocket.WebSocketTimeoutException:
                continue                    # a busy machine: keep waiting until the deadline
            if msg.get("id") == mid:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            if "method" in msg:
                self.events.append(msg)
        raise TimeoutError(method)

    def drain(self, seconds):
        import websocket
        end = time.time() + seconds
        self.ws.settimeout(0.2)
        while time.time() < end:
            try:
                msg = json.loads(self.ws.recv())
            except websocket.WebSocketTimeoutException:
                continue
            if "method" in msg:
                self.events.append(msg)

    def close(self):
        self.ws.close()


def check_page(page, screenshot=None, width: int = 1280, height: int = 1600, timeout: float = 60.0,
               chromium: str | None = None) -> PageCheck:
    """Load ``page`` (a file path or URL) in headless Chromium; return a :class:`PageCheck`."""
    import urllib.request
    exe = chromium or find_chromium()
    if exe is None:
        raise FileNotFoundError("no chromium on PATH; install the Debian packages chromium and chromium-driver "
                                "(bash .ci/setup)")
    url = page if "://" in str(page) else Path(page).resolve().as_uri()
    profile = Path(tempfile.mkdtemp(prefix="chromium-profile-"))
    proc = subprocess.Popen([exe, *FLAGS, f"--user-data-dir={profile}", "--remote-debugging-port=0",
                             f"--window-size={width},{height}", "about:blank"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    res = PageCheck(url)
    cdp = None
    try:
        port_file = profile / "DevToolsActivePort"
        end = time.time() + timeout
        while not port_file.exists() or not port_file.read_text().strip():
            if proc.poll() is not None:
                raise RuntimeError(f"chromium exited with {proc.returncode}: {proc.stderr.read().decode()[-2000:]}")
            if time.time() > end:
                raise TimeoutError("chromium did not open its DevTools port")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        targets = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10).read())
        ws = next(t["webSocketDebuggerUrl"] for t in targets if t.get("type") == "page")
        cdp = _CDP(ws, timeout)
        for dom in ("Runtime", "Log", "Network", "Page"):
            cdp.call(f"{dom}.enable")
        cdp.call("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1,
                                                        "mobile": False})
        cdp.call("Page.navigate", {"url": url})
        end = time.time() + timeout
        while time.time() < end and not any(e["method"] == "Page.loadEventFired" for e in cdp.events):
            cdp.drain(0.3)
        cdp.drain(0.5)
        info = cdp.call("Runtime.evaluate", {"expression": "JSON.stringify({t: document.title, "
                        "n: document.body ? document.body.innerText.length : 0, i: document.images.length, "
                        "b: Array.from(document.images).filter(x => !(x.complete && x.naturalWidth > 0)).length})",
                        "returnByValue": True})
        v = json.loads(info["result"]["value"])
        res.title, res.body_text_length, res.images, res.broken_images = v["t"], v["n"], v["i"], v["b"]
        if screenshot is not None:
            shot = cdp.call("Page.captureScreenshot", {"format": "png"})
            res.screenshot = Path(screenshot)
            res.screenshot.write_bytes(base64.b64decode(shot["data"]))
        for e in cdp.events:
            m, p = e["method"], e.get("params", {})
            if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                res.console_errors.append(" ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
            elif m == "Runtime.exceptionThrown":
                d = p.get("exceptionDetails", {})
                res.exceptions.append(d.get("exception", {}).get("description", d.get("text", "")))
            elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                res.log_errors.append(p["entry"].get("text", ""))
            elif m == "Network.requestWillBeSent":
                u = p.get("request", {}).get("url", "")
                if not u.startswith("data:") and u != url:
                    res.requests.append(u)
            elif m == "Network.loadingFailed":
                res.failed_requests.append(p.get("errorText", "") + " " + p.get("requestId", ""))
    finally:
        if cdp is not None:
            try:
                cdp.call("Browser.close", timeout=5)
            except Exception:  # noqa: BLE001 - the browser may already be gone
                pass
            cdp.close()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        shutil.rmtree(profile, ignore_errors=True)
    return res
