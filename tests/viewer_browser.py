"""Headless Chromium driven over the DevTools protocol, for screenshots of the Rerun web viewer.

What a person sees in the viewer was never tested by reading the .rrd back; this loads it the way
a user does: `rerun --serve-web` on 127.0.0.1, the page in Chromium (Debian's package), WebGL2
through SwiftShader (headless Chromium finds no WebGPU adapter), and a PNG of the page.

The DevTools protocol goes over a pipe (``--remote-debugging-pipe``: JSON messages, each ended by
a NUL byte, written to fd 3 and read from fd 4), so no port is opened and no websocket library
is needed. Waiting for the page: the viewer takes 15-40 s to load its wasm and the recording, so
callers take screenshots until the pixels show what they wait for; Chromium's
``--virtual-time-budget`` gave a black page.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path

CHROMIUM_NAMES = ("chromium", "chromium-browser")


def find_chromium() -> str | None:
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def ensure_chromium() -> tuple[str | None, str]:
    """(path to chromium, why not) : installs Debian's ``chromium`` with apt-get when missing
    (as root, or through passwordless sudo), so a fresh machine can run the browser tests."""
    found = find_chromium()
    if found:
        return found, ""
    if shutil.which("apt-get") is None:
        return None, "chromium is not installed and there is no apt-get to install it"
    prefix: list[str] = []
    if os.geteuid() != 0:
        if shutil.which("sudo") is None:
            return None, "chromium is not installed and installing it needs root (no sudo)"
        prefix = ["sudo", "-n"]
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    install = prefix + ["apt-get", "install", "-y", "--no-install-recommends", "chromium"]
    done = subprocess.run(install, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        # the package lists may be missing on a fresh image: update once and try again
        subprocess.run(prefix + ["apt-get", "update"], env=env, capture_output=True)
        done = subprocess.run(install, env=env, capture_output=True, text=True)
    found = find_chromium()
    if found:
        return found, ""
    tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["?"]
    return None, f"chromium could not be installed with apt-get: {tail[0]}"


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (the kernel's choice)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for_port(port: int, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise TimeoutError(f"nothing listens on 127.0.0.1:{port} after {timeout} s")


class Chromium:
    """One headless Chromium with one page, driven over ``--remote-debugging-pipe``.

    Use as a context manager: the browser process and its profile directory go at exit.
    """

    def __init__(self, executable: str, *, width: int = 1600, height: int = 1000) -> None:
        self.profile = tempfile.mkdtemp(prefix="isaac-chromium-")
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()
        # the child reads commands on fd 3 and writes answers on fd 4
        args = [
            executable,
            "--headless=new",
            "--no-sandbox",  # root in a container has no user namespace for the sandbox
            "--use-angle=swiftshader",  # WebGL2 on the CPU
            "--enable-unsafe-swiftshader",
            "--remote-debugging-pipe",
            f"--user-data-dir={self.profile}",
            f"--window-size={width},{height}",
            "--hide-scrollbars",
            "--mute-audio",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "about:blank",
        ]

        def child_fds() -> None:
            # via fresh descriptors: one of the pipe's own may already be 3 or 4
            r, w = os.dup(to_child_r), os.dup(from_child_w)
            os.dup2(r, 3)
            os.dup2(w, 4)

        self.proc = subprocess.Popen(
            args,
            # the pipes are close-on-exec; only the inheritable copies at 3 and 4 (dup2) reach
            # the browser (close_fds would close them: it runs after preexec_fn)
            close_fds=False,
            preexec_fn=child_fds,
            stdout=subprocess.DEVNULL,
            stderr=None if os.environ.get("ISAAC_CHROMIUM_LOG") else subprocess.DEVNULL,
            start_new_session=True,
        )
        os.close(to_child_r)
        os.close(from_child_w)
        self._next_id = 0
        self._buffer = b""
        self.session: str | None = None
        self.width, self.height = width, height

    def __enter__(self) -> Chromium:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self.call("Browser.close", timeout=5)
            except Exception:  # noqa: BLE001 - killed below
                pass
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        for fd in (self._to_child, self._from_child):
            try:
                os.close(fd)
            except OSError:
                pass
        shutil.rmtree(self.profile, ignore_errors=True)

    def _read_message(self, deadline: float) -> dict:
        import select

        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError("chromium did not answer")
            ready, _, _ = select.select([self._from_child], [], [], left)
            if ready:
                chunk = os.read(self._from_child, 1 << 20)
                if not chunk:
                    raise RuntimeError("chromium closed its DevTools pipe")
                self._buffer += chunk
        raw, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(raw)

    def call(self, method: str, params: dict | None = None, *, timeout: float = 60.0) -> dict:
        """Send one command (to the page's session once `open` attached one); its result."""
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params or {}}
        if self.session is not None and not method.startswith(("Target.", "Browser.")):
            message["sessionId"] = self.session
        os.write(self._to_child, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            answer = self._read_message(deadline)
            if answer.get("id") == self._next_id:  # events in between are dropped
                if "error" in answer:
                    raise RuntimeError(f"{method}: {answer['error']}")
                return answer.get("result", {})

    def open(self, url: str) -> None:
        """A new page at ``url`` of the window's size, attached as this object's session."""
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})[
            "sessionId"
        ]
        self.call(
            "Emulation.setDeviceMetricsOverride",
            {"width": self.width, "height": self.height, "deviceScaleFactor": 1, "mobile": False},
        )
        self.call("Page.enable")
        self.call("Page.navigate", {"url": url})

    def evaluate(self, expression: str):
        got = self.call("Runtime.evaluate", {"expression": expression, "returnByValue": True})
        return got.get("result", {}).get("value")

    def screenshot(self, path: str | Path) -> Path:
        data = self.call("Page.captureScreenshot", {"format": "png"}, timeout=120)["data"]
        path = Path(path)
        path.write_bytes(base64.b64decode(data))
        return path


class WebViewer:
    """``rerun --serve-web`` on 127.0.0.1 for one .rrd, on free ports; stopped at exit."""

    def __init__(self, rrd: str | Path, *, rerun: str | None = None) -> None:
        from isaac.app.logs import rerun_executable

        rerun = rerun or rerun_executable()
        self.grpc_port, self.web_port = free_port(), free_port()
        self.proc = subprocess.Popen(
            [
                rerun,
                "--serve-web",
                "--bind",
                "127.0.0.1",
                "--port",
                str(self.grpc_port),
                "--web-viewer-port",
                str(self.web_port),
                str(rrd),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        wait_for_port(self.web_port, 60)
        wait_for_port(self.grpc_port, 60)
        proxy = f"rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{self.grpc_port}%2Fproxy"
        self.url = f"http://127.0.0.1:{self.web_port}/?url={proxy}&renderer=webgl"

    def __enter__(self) -> WebViewer:
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGTERM)  # its own session: the viewer's group
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
