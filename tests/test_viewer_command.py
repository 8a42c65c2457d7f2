"""``isaac view``: without a display it serves the web viewer on 127.0.0.1 and prints one URL;
SIGTERM stops the viewer it started and leaves no temporary file, and SIGKILL takes the viewer
with it; a bad address or port is one line before the viewer starts; a .mcap's Rerun copy is
kept next to the log and reused while the log is unchanged."""

from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent / "recorder"))
from test_recorder_mcap import PYTHON, REPO, record_run, run_cli  # noqa: E402


def listening_sockets(port: int) -> list[str]:
    """Local addresses (hex, as in /proc/net/tcp*) of the listening TCP sockets on ``port``."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not os.path.exists(table):
            continue
        with open(table) as f:
            next(f)
            for line in f:
                fields = line.split()
                address, hex_port = fields[1].split(":")
                if fields[3] == "0A" and int(hex_port, 16) == port:  # 0A: LISTEN
                    found.append(address)
    return found


def children(pid: int) -> list[int]:
    with open(f"/proc/{pid}/task/{pid}/children") as f:
        return [int(x) for x in f.read().split()]


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "Ctrl-C"])
def test_view_without_a_display_serves_localhost_and_a_signal_leaves_nothing_behind(
    tmp_path, signum
):
    logs, tmp = tmp_path / "logs", tmp_path / "tmp"
    logs.mkdir()
    tmp.mkdir()
    log = logs / "run.mcap"
    record_run(log, n=6, contacts=2, steps=20)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["TMPDIR"] = str(tmp)
    proc = subprocess.Popen(
        [PYTHON, "-m", "isaac", "view", str(log)],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 180)
        assert ready, "no URL printed within 180 s"
        url = proc.stdout.readline().strip()
        # one clean line: the URL of the web viewer, its gRPC proxy on the same host
        m = re.fullmatch(
            r"http://127\.0\.0\.1:(\d+)/\?url=rerun%2Bhttp%3A%2F%2F127\.0\.0\.1%3A(\d+)%2Fproxy",
            url,
        )
        assert m, url
        http_port, grpc_port = int(m.group(1)), int(m.group(2))
        for port in (http_port, grpc_port):
            # bound to the loopback address only (127.0.0.1 is 0100007F in /proc/net/tcp)
            assert listening_sockets(port) == ["0100007F"], (port, listening_sockets(port))
        viewers = children(proc.pid)  # the viewer and its watchdog
        assert len(viewers) == 2 and all(alive(p) for p in viewers)
        assert any(tmp.iterdir())  # its temporary directory, while it runs
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + signum
    assert "no display" in err and "web viewer" in err
    assert "Traceback" not in err
    deadline = time.monotonic() + 10
    while any(alive(p) for p in viewers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(alive(p) for p in viewers), "the viewer outlived isaac view"
    assert not listening_sockets(http_port) and not listening_sockets(grpc_port)
    assert list(tmp.iterdir()) == []
    # next to the log: only the log and its kept Rerun copy (no .partial)
    assert sorted(p.name for p in logs.iterdir()) == ["run.mcap", "run.mcap.rrd"]


def test_view_keeps_the_rerun_copy_of_an_mcap_log_while_the_log_is_unchanged(tmp_path):
    log = tmp_path / "run.mcap"
    record_run(log, n=5, contacts=2, steps=15)
    copy = Path(str(log) + ".rrd")
    out = run_cli("view", str(log), "--web", "--dry-run")
    assert out.returncode == 0, out.stderr
    assert str(copy) in out.stdout.split()
    first = os.stat(copy)
    assert first.st_mtime_ns == os.stat(log).st_mtime_ns
    assert run_cli("view", str(log), "--web", "--dry-run").returncode == 0
    assert os.stat(copy).st_ino == first.st_ino  # reused, not written again
    # the log changes (here: its time): converted again
    os.utime(log, ns=(first.st_atime_ns, first.st_mtime_ns + 1_000_000_000))
    assert run_cli("view", str(log), "--web", "--dry-run").returncode == 0
    second = os.stat(copy)
    assert second.st_ino != first.st_ino
    assert second.st_mtime_ns == os.stat(log).st_mtime_ns
    # --fresh converts even a current copy
    assert run_cli("view", str(log), "--web", "--dry-run", "--fresh").returncode == 0
    assert os.stat(copy).st_ino != second.st_ino


def test_view_binds_127_0_0_1_unless_told_and_takes_the_ports_given(tmp_path):
    log = tmp_path / "run.rrd"
    record_run(tmp_path / "run.mcap", n=4, contacts=1, steps=5, rrd=log)
    out = run_cli("view", str(log), "--dry-run")
    command = out.stdout.split()
    assert command[command.index("--bind") + 1] == "127.0.0.1"
    assert int(command[command.index("--port") + 1]) > 0  # a free port, not Rerun's 9876
    out = run_cli(
        "view", str(log), "--web", "--bind", "0.0.0.0", "--port", "8123", "--grpc-port", "8124",
        "--dry-run",
    )  # fmt: skip
    command = out.stdout.split()
    assert command[command.index("--bind") + 1] == "0.0.0.0"
    assert command[command.index("--web-viewer-port") + 1] == "8123"
    assert command[command.index("--port") + 1] == "8124"


URL = re.compile(
    r"http://(?P<host>[^/]+):(?P<http>\d+)/\?url=rerun%2Bhttp%3A%2F%2F(?P<proxy>.+)%3A(?P<grpc>\d+)%2Fproxy"
)


def start_view(log, *args):
    """`isaac view LOG --web ARGS` (a new user's command), its URL once printed, as a match of
    URL."""
    proc = subprocess.Popen(
        [PYTHON, "-m", "isaac", "view", str(log), "--web", *args],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    ready, _, _ = select.select([proc.stdout], [], [], 180)
    if not ready:
        proc.kill()
        proc.wait()
        pytest.fail("no URL printed within 180 s")
    url = proc.stdout.readline().strip()
    m = URL.fullmatch(url)
    if m is None:
        proc.kill()
        proc.wait()
        pytest.fail(f"not the viewer's URL: {url!r}")
    return proc, m


def group_of(pid: int) -> list[int]:
    """The live processes (not zombies) of process group ``pid``."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pid and fields[0] != "Z":  # fields: state, ppid, pgrp
            found.append(int(entry))
    return found


def test_view_killed_with_sigkill_takes_its_viewer_with_it(tmp_path):
    log = tmp_path / "run.rrd"
    record_run(tmp_path / "run.mcap", n=4, contacts=1, steps=10, rrd=log)
    proc, m = start_view(log)
    groups = set()
    try:
        ports = int(m["http"]), int(m["grpc"])
        groups = {os.getpgid(p) for p in children(proc.pid)}
        assert all(listening_sockets(port) for port in ports)
        proc.kill()  # SIGKILL: no clean-up of its own runs
        proc.wait(timeout=10)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and (
            any(group_of(g) for g in groups) or any(listening_sockets(p) for p in ports)
        ):
            time.sleep(0.1)
        assert not any(group_of(g) for g in groups), "the viewer outlived a killed isaac view"
        assert not any(listening_sockets(p) for p in ports)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for g in groups:  # what a failed run of this test left
            if group_of(g):
                os.killpg(g, signal.SIGKILL)


def test_view_on_the_ipv6_loopback_prints_its_address_in_brackets(tmp_path):
    import socket

    try:
        with socket.socket(socket.AF_INET6) as s:
            s.bind(("::1", 0))
    except OSError:
        pytest.skip("no IPv6 loopback here")
    log = tmp_path / "run.rrd"
    record_run(tmp_path / "run.mcap", n=4, contacts=1, steps=10, rrd=log)
    proc, m = start_view(log, "--bind", "::1")
    try:
        assert m["host"] == "[::1]" and m["proxy"] == "%5B%3A%3A1%5D"  # [::1], URL-quoted
        # ::1 is 00000000000000000000000001000000 in /proc/net/tcp6
        assert listening_sockets(int(m["http"])) == ["00000000000000000000000001000000"]
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + signal.SIGTERM


@pytest.mark.parametrize(
    "option, value",
    [
        ("--bind", "999.1.1.1"),
        ("--bind", "example.invalid"),
        ("--bind", "192.0.2.1"),  # TEST-NET-1: a valid address, of no interface here
        ("--port", "99999"),
        ("--port", "-1"),
        ("--grpc-port", "abc"),
        ("--grpc-port", "1e400"),
    ],
)
def test_view_refuses_a_bad_address_or_port_in_one_line_before_starting(tmp_path, option, value):
    log = tmp_path / "run.rrd"
    record_run(tmp_path / "run.mcap", n=4, contacts=1, steps=5, rrd=log)
    out = run_cli("view", str(log), "--web", option, value)
    assert out.returncode == 2, out.stderr
    (line,) = out.stderr.splitlines()
    assert line.startswith("isaac view: error: ") and option in line and value in line, line
    assert out.stdout == ""


def test_view_takes_localhost_as_127_0_0_1_and_refuses_one_port_for_both(tmp_path):
    log = tmp_path / "run.rrd"
    record_run(tmp_path / "run.mcap", n=4, contacts=1, steps=5, rrd=log)
    command = run_cli("view", str(log), "--bind", "localhost", "--dry-run").stdout.split()
    assert command[command.index("--bind") + 1] == "127.0.0.1"
    out = run_cli("view", str(log), "--web", "--port", "8125", "--grpc-port", "8125")
    assert out.returncode == 2
    assert (
        out.stderr.strip()
        == "isaac view: error: --grpc-port and --port must differ, got 8125 for both"
    )
