"""Debian's headless Chromium (chromium-headless-shell, tools/apt-packages-test.txt) driven over
the DevTools protocol on a pipe (--remote-debugging-pipe: no port, nothing on the network): open a
page, collect what its console said and which URLs it fetched, evaluate JavaScript, screenshot an
element. For the tests that look at a page as its reader would (test_report_html.py)."""

from __future__ import annotations

import base64
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

BROWSER = "chromium-headless-shell"


def browser_path() -> str | None:
    return shutil.which(BROWSER, path="/usr/local/bin:/usr/bin:/bin")


class Browser:
    """One headless browser with one page; events are kept in `events` as they arrive."""

    def __init__(self, width: int = 1280, height: int = 900) -> None:
        exe = browser_path()
        assert exe, f"{BROWSER} is missing: tools/armctl test installs it (tools/apt-packages-test.txt)"
        self.profile = tempfile.mkdtemp(prefix="armctl-chromium-")
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()

        def pipes_on_3_and_4() -> None:  # the DevTools pipe: the browser reads fd 3, writes fd 4
            os.dup2(to_child_r, 100)  # out of the way first: either end may be fd 3 or 4 itself
            os.dup2(from_child_w, 101)
            os.dup2(100, 3)  # dup2 leaves its copy inheritable, unlike os.pipe()'s
            os.dup2(101, 4)

        self.proc = subprocess.Popen(
            [exe, "--headless", "--remote-debugging-pipe", "--no-sandbox", "--disable-gpu", "--no-first-run",
             "--disable-extensions", "--disable-background-networking", "--disable-sync", "--mute-audio",
             f"--user-data-dir={self.profile}", f"--window-size={width},{height}", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
            preexec_fn=pipes_on_3_and_4, close_fds=False)
        os.close(to_child_r)
        os.close(from_child_w)
        self._buf = b""
        self._id = 0
        self.events: list[dict[str, Any]] = []
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Page", "Runtime", "Log", "Network"):
            self.call(f"{domain}.enable", session=True)
        self.call("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1,
                                                          "mobile": False}, session=True)

    def _read(self, timeout: float) -> dict[str, Any] | None:
        deadline = time.monotonic() + timeout
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            ready, _, _ = select.select([self._from_child], [], [], left)
            if ready:
                chunk = os.read(self._from_child, 1 << 20)
                assert chunk, f"the browser closed its pipe: {self.proc.stderr.read().decode()[-2000:] if self.proc.poll() is not None else ''}"
                self._buf += chunk
        msg, _, self._buf = self._buf.partition(b"\0")
        return json.loads(msg)

    def call(self, method: str, params: dict[str, Any] | None = None, session: bool = False,
             timeout: float = 60.0) -> dict[str, Any]:
        self._id += 1
        msg: dict[str, Any] = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = self.session
        os.write(self._to_child, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            got = self._read(max(0.0, deadline - time.monotonic()))
            assert got is not None, f"{method}: no answer in {timeout:g} s"
            if got.get("id") == self._id:
                assert "error" not in got, f"{method}: {got['error']}"
                return got.get("result", {})
            self.events.append(got)

    def wait_for(self, method: str, timeout: float = 60.0) -> dict[str, Any]:
        for ev in self.events:
            if ev.get("method") == method:
                return ev
        deadline = time.monotonic() + timeout
        while True:
            got = self._read(max(0.0, deadline - time.monotonic()))
            assert got is not None, f"no {method} in {timeout:g} s"
            self.events.append(got)
            if got.get("method") == method:
                return got

    def open(self, path: Path, timeout: float = 120.0) -> None:
        self.call("Page.navigate", {"url": path.resolve().as_uri()}, session=True)
        self.wait_for("Page.loadEventFired", timeout)

    def evaluate(self, js: str) -> Any:
        r = self.call("Runtime.evaluate", {"expression": js, "returnByValue": True, "awaitPromise": True},
                      session=True)
        assert "exceptionDetails" not in r, f"{js[:80]}...: {r['exceptionDetails']}"
        return r["result"].get("value")

    def screenshot_of(self, selector: str, index: int) -> tuple[bytes, dict[str, float]]:
        """PNG of the index-th element the CSS selector finds, scrolled into the viewport (a capture
        beyond the viewport resizes the page, which moves what it measured), and its box."""
        box = self.evaluate(f"""(() => {{ const e = document.querySelectorAll({json.dumps(selector)})[{index}];
            e.scrollIntoView({{block: "start"}}); const r = e.getBoundingClientRect();
            return {{x: r.x + window.scrollX, y: r.y + window.scrollY, width: r.width, height: r.height}}; }})()""")
        r = self.call("Page.captureScreenshot", {"format": "png", "clip": {**box, "scale": 1}}, session=True)
        return base64.b64decode(r["data"]), box

    def console_errors(self) -> list[str]:
        """Every error the page reported: console.error, an uncaught exception, a failed load."""
        out = []
        for ev in self.events:
            p = ev.get("params", {})
            if ev.get("method") == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                out.append(" ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
            elif ev.get("method") == "Runtime.exceptionThrown":
                d = p.get("exceptionDetails", {})
                out.append(d.get("exception", {}).get("description") or d.get("text", "exception"))
            elif ev.get("method") == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                out.append(p["entry"].get("text", ""))
        return out

    def requested_urls(self) -> list[str]:
        return [ev["params"]["request"]["url"] for ev in self.events if ev.get("method") == "Network.requestWillBeSent"]

    def close(self) -> None:
        try:
            self.call("Browser.close", timeout=10)
        except AssertionError:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for fd in (self._to_child, self._from_child):
            os.close(fd)
        if self.proc.stderr:
            self.proc.stderr.close()
        shutil.rmtree(self.profile, ignore_errors=True)


def page_facts(browser: Browser, page: Path) -> dict[str, Any]:
    """What a reader's browser made of a page once every folded section is opened and its figures are
    drawn (if it has any): its title,
    the scripts but those with JSON, images not inlined, elements with an event handler, links out,
    every element's kind, its text and its figures' SVG text (tests/python/test_attacks.py,
    test_hostile_names.py: no element of a name's)."""
    browser.events.clear()  # a browser used before holds the last page's load event
    browser.open(page)
    for _ in range(600):
        if browser.evaluate("document.body.dataset.figures") == "drawn" or not browser.evaluate(
                "document.querySelector('div.figure[data-figure]')"):
            break
        browser.call("Runtime.evaluate", {"expression": "new Promise(r => setTimeout(r, 100))", "awaitPromise": True},
                     session=True)
    browser.evaluate("document.querySelectorAll('details').forEach(d => { d.open = true; })")  # a reader opens them
    for _ in range(600):  # and their figures are drawn then
        if browser.evaluate("document.querySelectorAll('div.figure[data-figure]').length === "
                            "document.querySelectorAll('div.figure[data-drawn=\"yes\"]').length"):
            break
        browser.call("Runtime.evaluate", {"expression": "new Promise(r => setTimeout(r, 100))", "awaitPromise": True},
                     session=True)
    return browser.evaluate("""({
        title: document.title,
        scripts: Array.from(document.scripts).filter(s => s.type !== 'application/json').length,
        elements: Array.from(document.querySelectorAll('main *')).map(e => e.tagName.toLowerCase()),
        foreign_images: document.querySelectorAll('img:not([src^="data:"])').length,
        handlers: Array.from(document.querySelectorAll('*')).filter(e => Array.from(e.attributes).some(
            a => a.name.startsWith('on'))).length,
        links: document.querySelectorAll('a[href]:not([href^="#"])').length,
        svg_links: document.querySelectorAll('svg a').length,
        text: document.body.innerText,
        svg_text: Array.from(document.querySelectorAll('svg text, svg tspan')).map(t => t.textContent).join('\\n'),
    })""")
