"""Open a page in a real headless Chromium (Debian's `chromium` package) through the DevTools protocol.

`load_page(path)` starts /usr/bin/chromium --headless with a private profile, navigates to the
file, waits for the load event and returns what a person would check: the title, the visible text,
how many images there are and how many decoded (complete with a natural width), the console errors
and uncaught exceptions, and (optionally) a screenshot. `requires_chromium` skips with a reason
where Chromium or websocket-client is missing (.ci/run installs both).
"""
from __future__ import annotations

import base64
import importlib.util
import json
import os
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

import pytest

CHROMIUM = next((p for p in ("/usr/bin/chromium", shutil.which("chromium") or "",
                             shutil.which("chromium-browser") or "") if p and os.path.exists(p)), None)
_why = ("Chromium not installed (apt-get install chromium)" if CHROMIUM is None else
        "websocket-client not installed (pip install websocket-client)" if importlib.util.find_spec("websocket") is None
        else "")
requires_chromium = pytest.mark.skipif(bool(_why), reason=_why or "ok")

_IMAGES_JS = ("JSON.stringify({total: document.images.length, "
              "loaded: Array.from(document.images).filter(i => i.complete && i.naturalWidth > 0).length, "
              "external: Array.from(document.querySelectorAll('[src],[href]')).filter(e => "
              "!/^(data:|#|about:)/.test(e.getAttribute('src') || e.getAttribute('href') || '#')).length, "
              "title: document.title, text: document.body.innerText, "
              "tables: document.querySelectorAll('table').length})")


class _Client:
    def __init__(self, ws_url: str) -> None:
        import websocket

        self.ws = websocket.create_connection(ws_url, timeout=30, suppress_origin=True)
        self.next_id = 0
        self.events: list[dict] = []

    def call(self, method: str, **params):
        self.next_id += 1
        my_id = self.next_id
        self.ws.send(json.dumps({"id": my_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == my_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})
            self.events.append(msg)

    def wait_for(self, method: str, timeout: float = 30.0) -> dict:
        end = time.monotonic() + timeout
        for ev in self.events:
            if ev.get("method") == method:
                return ev
        while time.monotonic() < end:
            msg = json.loads(self.ws.recv())
            self.events.append(msg)
            if msg.get("method") == method:
                return msg
        raise TimeoutError(f"no {method} within {timeout} s")


def load_page(path: str | Path, screenshot: str | Path | None = None, settle_s: float = 0.3) -> dict:
    """Load `path` in headless Chromium; return title, text, images_total, images_loaded,
    external_refs (src/href not data: or #), tables, console_errors (list of strings)."""
    profile = tempfile.mkdtemp(prefix="impactval-chromium-")
    proc = subprocess.Popen([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                             "--disable-extensions", "--remote-debugging-port=0", "--remote-allow-origins=*",
                             f"--user-data-dir={profile}", "--window-size=1280,1600", "about:blank"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        port_file = Path(profile) / "DevToolsActivePort"
        end = time.monotonic() + 60
        while not (port_file.exists() and port_file.read_text().strip()):
            if proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError("Chromium did not start its DevTools endpoint")
            time.sleep(0.1)
        port = int(port_file.read_text().split()[0])
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as fh:
            targets = json.load(fh)
        page = next(t for t in targets if t.get("type") == "page")
        client = _Client(page["webSocketDebuggerUrl"])
        for domain in ("Page", "Runtime", "Log"):
            client.call(f"{domain}.enable")
        client.call("Page.navigate", url=Path(path).resolve().as_uri())
        client.wait_for("Page.loadEventFired")
        time.sleep(settle_s)
        info = json.loads(client.call("Runtime.evaluate", expression=_IMAGES_JS, returnByValue=True)["result"]["value"])
        if screenshot is not None:
            shot = client.call("Page.captureScreenshot", format="png", captureBeyondViewport=True)
            Path(screenshot).write_bytes(base64.b64decode(shot["data"]))
        errors = []
        for ev in client.events:
            m, p = ev.get("method"), ev.get("params", {})
            if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
                errors.append(" ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
            elif m == "Runtime.exceptionThrown":
                errors.append(p.get("exceptionDetails", {}).get("text", "exception"))
            elif m == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
                errors.append(p["entry"].get("text", ""))
        client.ws.close()
        return {"title": info["title"], "text": info["text"], "images_total": info["total"],
                "images_loaded": info["loaded"], "external_refs": info["external"], "tables": info["tables"],
                "console_errors": errors}
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        shutil.rmtree(profile, ignore_errors=True)
