"""Opens a page in headless Chromium and reports what it shows, for the preview page's test.

Chromium is driven through the DevTools protocol over a pipe (--remote-debugging-pipe: JSON
messages ending in NUL on file descriptors 3 and 4), so no WebSocket library is needed. Real
time is used, not --virtual-time-budget: the page decodes Draco in a Web Worker, which virtual
time does not wait for.
"""
import base64
import fcntl
import json
import os
import shutil
import subprocess
import tempfile
import time


def find_chromium():
    """The Chromium executable on PATH (Debian's package `chromium`), or None."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


class _DevTools:
    def __init__(self, chromium, profile):
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()
        args = [chromium, "--headless", "--no-sandbox", "--remote-debugging-pipe", "--user-data-dir=" + profile,
                "--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--window-size=1000,700",
                "--no-first-run", "--disable-extensions", "about:blank"]

        def child_fds():
            # The pipe ends the browser reads and writes become its descriptors 3 and 4 (moved
            # above 4 first, as either may be 3 or 4 already); subprocess keeps pass_fds open.
            read_end = fcntl.fcntl(to_browser_r, fcntl.F_DUPFD, 10)
            write_end = fcntl.fcntl(from_browser_w, fcntl.F_DUPFD, 10)
            os.dup2(read_end, 3)
            os.dup2(write_end, 4)

        self._proc = subprocess.Popen(args, pass_fds=(3, 4), preexec_fn=child_fds,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._buffer = b""
        self._next_id = 0
        self.console = []

    def call(self, method, session=None, **params):
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params}
        if session:
            message["sessionId"] = session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._read()
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError("%s: %s" % (method, reply["error"]))
                return reply.get("result", {})

    def _read(self):
        while b"\0" not in self._buffer:
            chunk = os.read(self._from_browser, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the DevTools pipe")
            self._buffer += chunk
        text, self._buffer = self._buffer.split(b"\0", 1)
        message = json.loads(text)
        if message.get("method") == "Runtime.consoleAPICalled":
            self.console.append(" ".join(str(a.get("value", a.get("description", ""))) for a in
                                         message["params"]["args"]))
        elif message.get("method") == "Runtime.exceptionThrown":
            self.console.append(message["params"]["exceptionDetails"].get("exception", {}).get("description", ""))
        return message

    def close(self):
        try:
            self.call("Browser.close")
        except (RuntimeError, OSError):
            pass
        try:
            self._proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        os.close(self._to_browser)
        os.close(self._from_browser)


def open_page(chromium, path, ready_expression, queries, timeout=60.0):
    """Loads the file `path`, waits (at most `timeout` seconds) until the JavaScript
    `ready_expression` is truthy, then evaluates each of `queries` (name -> JavaScript) and
    takes a screenshot. Returns {"ready": the expression's last value, name: each query's
    value, "png": the screenshot's bytes, "console": console messages and exceptions}."""
    profile = tempfile.mkdtemp(prefix="mlfe-chromium-")
    tools = _DevTools(chromium, profile)
    try:
        target = tools.call("Target.createTarget", url="about:blank")["targetId"]
        session = tools.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        tools.call("Runtime.enable", session)
        tools.call("Page.navigate", session, url="file://" + os.path.abspath(path))

        def evaluate(expression):
            r = tools.call("Runtime.evaluate", session, expression=expression, returnByValue=True)
            return r.get("result", {}).get("value")

        out = {"ready": None}
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not out["ready"]:
            out["ready"] = evaluate(ready_expression)
            if not out["ready"]:
                time.sleep(0.2)
        for name, expression in queries.items():
            out[name] = evaluate(expression)
        out["png"] = base64.b64decode(tools.call("Page.captureScreenshot", session, format="png")["data"])
        out["console"] = list(tools.console)
        return out
    finally:
        tools.close()
        shutil.rmtree(profile, ignore_errors=True)
