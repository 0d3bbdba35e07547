"""Headless Chromium for reports: print the page to PDF, and load it the way a reader would,
collecting console errors, failed or network requests, broken images and a screenshot.

Chromium is driven over its DevTools protocol through a pipe (`--remote-debugging-pipe`: commands
on file descriptor 3, replies and events on 4, NUL-terminated JSON), so no port is opened and no
websocket client is needed. The flags keep it off the network and out of the user's profile: a
fresh profile folder per launch, no background networking, component updates or sync (without
them Chromium waits on refused connections on a machine without network).
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from orthosim.storage.atomic import write_bytes
from orthosim.errors import OrthosimError

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-default-apps", "--disable-extensions", "--hide-scrollbars", "--mute-audio")
NAMES = ("chromium", "chromium-browser", "google-chrome", "chrome")


class BrowserError(OrthosimError):
    """Chromium is missing, or failed to load or print a page."""


def find_chromium() -> str:
    for name in NAMES:
        path = shutil.which(name)
        if path:
            return path
    raise BrowserError(None, "--pdf", "needs headless Chromium, which is not installed",
                       "install it (bash tools/dev.sh install, or apt-get install chromium)")


@dataclass
class PageLoad:
    """What loading a page showed: problems a reader would meet, and how it looked."""

    url: str
    console_errors: list[str] = field(default_factory=list)  # console.error, uncaught exceptions, log errors
    failed_requests: list[str] = field(default_factory=list)  # URL and reason of every request that failed
    network_requests: list[str] = field(default_factory=list)  # requests for anything but file: and data: URLs
    broken_images: list[str] = field(default_factory=list)  # <img> that did not decode
    images: int = 0
    screenshot_png: bytes = b""
    pdf: bytes = b""
    value: object = None  # what `evaluate` gave, when asked

    @property
    def problems(self) -> list[str]:
        return ([f"console: {e}" for e in self.console_errors] + [f"failed: {e}" for e in self.failed_requests]
                + [f"network: {e}" for e in self.network_requests] + [f"broken image: {e}" for e in self.broken_images])


class _DevTools:
    """One Chromium process and its DevTools pipe."""

    def __init__(self, window: tuple[int, int], timeout_s: float, extra_flags: tuple[str, ...] = ()):
        self.timeout_s = timeout_s
        self.profile = tempfile.TemporaryDirectory(prefix="orthosim-chromium-")
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()

        def wire():
            # In the child: the pipe ends on the descriptors Chromium expects. dup2 makes them
            # inheritable; every other descriptor Python opened is not, so exec closes it.
            # (pass_fds cannot do this: it closes what is not listed after this function runs.)
            # Both are first moved above 4, in case one of them is 3 or 4 already.
            r, w = fcntl.fcntl(to_child_r, fcntl.F_DUPFD, 10), fcntl.fcntl(from_child_w, fcntl.F_DUPFD, 10)
            os.dup2(r, 3)
            os.dup2(w, 4)

        cmd = [find_chromium(), *FLAGS, *extra_flags, f"--user-data-dir={self.profile.name}", "--remote-debugging-pipe",
               f"--window-size={window[0]},{window[1]}", "about:blank"]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     close_fds=False, preexec_fn=wire)
        os.close(to_child_r)
        os.close(from_child_w)
        self._buf = b""
        self._next_id = 0
        self.events: list[dict] = []
        self.session: str | None = None

    def send(self, method: str, params: dict | None = None, session: bool = True) -> dict:
        self._next_id += 1
        msg = {"id": self._next_id, "method": method, "params": params or {}}
        if session and self.session:
            msg["sessionId"] = self.session
        os.write(self._to_child, json.dumps(msg).encode() + b"\0")
        while True:
            reply = self._read()
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise BrowserError(None, method, f"failed in Chromium: {reply['error'].get('message')}", None)
                return reply.get("result", {})
            self.events.append(reply)

    def wait_for(self, method: str) -> dict:
        for i, e in enumerate(self.events):
            if e.get("method") == method:
                return self.events.pop(i)
        while True:
            e = self._read()
            if e.get("method") == method:
                return e
            self.events.append(e)

    def _read(self) -> dict:
        deadline = time.monotonic() + self.timeout_s
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            ready, _, _ = select.select([self._from_child], [], [], max(left, 0))
            if not ready:
                raise BrowserError(None, None, f"Chromium did not answer within {self.timeout_s:.0f} s", None)
            chunk = os.read(self._from_child, 1 << 20)
            if not chunk:
                raise BrowserError(None, None, "Chromium exited before answering", "check that `chromium --headless` runs here")
            self._buf += chunk
        line, self._buf = self._buf.split(b"\0", 1)
        return json.loads(line)

    def close(self) -> None:
        try:
            if self.proc.poll() is None:
                try:
                    os.write(self._to_child, json.dumps({"id": 0, "method": "Browser.close"}).encode() + b"\0")
                    self.proc.wait(timeout=10)
                except (OSError, subprocess.TimeoutExpired):
                    self.proc.kill()
                    self.proc.wait()
        finally:
            for fd in (self._to_child, self._from_child):
                try:
                    os.close(fd)
                except OSError:
                    pass
            self.profile.cleanup()


def load_page(page: str | Path, *, screenshot: bool = True, pdf: bool = False, window: tuple[int, int] = (1400, 1800),
              timeout_s: float = 60.0, fragment: str = "", extra_flags: tuple[str, ...] = (),
              evaluate: str | None = None) -> PageLoad:
    """Open the local file `page` (with `#fragment` when given) in headless Chromium and report what a
    reader would meet; `evaluate`: a JavaScript expression whose value, once loaded, is kept in `value`."""
    page = Path(page).resolve()
    url = page.as_uri() + (f"#{fragment}" if fragment else "")
    result = PageLoad(url)
    tools = _DevTools(window, timeout_s, extra_flags)
    try:
        target = tools.send("Target.createTarget", {"url": "about:blank"}, session=False)["targetId"]
        tools.session = tools.send("Target.attachToTarget", {"targetId": target, "flatten": True}, session=False)["sessionId"]
        for domain in ("Page", "Runtime", "Log", "Network"):
            tools.send(f"{domain}.enable")
        tools.send("Page.navigate", {"url": url})
        tools.wait_for("Page.loadEventFired")
        status = tools.send("Runtime.evaluate", {"expression": (
            "JSON.stringify({n: document.images.length, broken: Array.from(document.images)"
            ".filter(i => !i.complete || i.naturalWidth === 0).map(i => i.getAttribute('src'))})"),
            "returnByValue": True})
        info = json.loads(status["result"]["value"])
        result.images, result.broken_images = int(info["n"]), list(info["broken"])
        if evaluate is not None:
            result.value = tools.send("Runtime.evaluate", {"expression": evaluate, "returnByValue": True})["result"].get("value")
        if screenshot:
            shot = tools.send("Page.captureScreenshot", {"format": "png"})
            result.screenshot_png = base64.b64decode(shot["data"])
        if pdf:
            printed = tools.send("Page.printToPDF", {"printBackground": True, "preferCSSPageSize": False,
                                                     "landscape": True, "paperWidth": 11.69, "paperHeight": 8.27,
                                                     "marginTop": 0.3, "marginBottom": 0.3, "marginLeft": 0.3,
                                                     "marginRight": 0.3})
            result.pdf = base64.b64decode(printed["data"])
        requests: dict[str, str] = {}
        for e in tools.events:
            method, params = e.get("method"), e.get("params", {})
            if method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                result.console_errors.append(" ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", [])))
            elif method == "Runtime.exceptionThrown":
                d = params.get("exceptionDetails", {})
                result.console_errors.append(d.get("exception", {}).get("description") or d.get("text", "exception"))
            elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
                entry = params["entry"]
                result.console_errors.append(f"{entry.get('text')} {entry.get('url', '')}".strip())
            elif method == "Network.requestWillBeSent":
                u = params.get("request", {}).get("url", "")
                requests[params.get("requestId")] = u
                if not u.startswith(("file:", "data:", "about:")):
                    result.network_requests.append(u)
            elif method == "Network.loadingFailed":
                result.failed_requests.append(f"{requests.get(params.get('requestId'), '?')} ({params.get('errorText')})")
    finally:
        tools.close()
    return result


def print_pdf(page: str | Path, out: str | Path) -> Path:
    """Print the local page `page` to the PDF `out` (A4 landscape, backgrounds kept), atomically."""
    loaded = load_page(page, screenshot=False, pdf=True)
    if loaded.broken_images or loaded.failed_requests:
        raise BrowserError(page, None, f"did not load whole: {'; '.join(loaded.problems[:3])}",
                           "write the report again (orthosim report ... --pdf)")
    write_bytes(out, loaded.pdf)
    return Path(out)
