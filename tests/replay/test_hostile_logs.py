"""Whatever the file, `inspect`, `replay`, `diff` and `recover` end in a verdict or one line:
no traceback, no hang, no memory blown.

- a FIFO, a device or a directory is refused from ``os.stat`` before any open (opening a FIFO
  for reading waits for a writer: the issue found `inspect`, `replay` and `recover` hanging);
- well-formed logs holding malformed metadata or messages (settings ``[]`` or ``null``, a
  ``/bodies`` array one value short, a ``/world`` polygon with an odd number of coordinates, a
  contact naming body 999) are "damaged log" errors, exit 2 (the issue found tracebacks);
- a crafted sparse file whose one chunk claims 6 GiB is refused before anything is allocated,
  under a 1 GiB address-space limit (the issue measured more than 3 GB);
- 300 fuzzed logs (bytes edited, cut, records crafted, content made wrong behind consistent
  CRCs; fixed seed) give a Report or a LogError / SceneError, each within a deadline.
"""

from __future__ import annotations

import contextlib
import os
import resource
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from isaac.app.cli import main
from isaac.errors import LogError, SceneError
from recorder.mcap_records import MAX_RECORD_BYTES
from recorder.reader import LogReader, recover
from replay.compare import diff_logs, replay_log

sys.path.insert(0, str(Path(__file__).parent))
from mcap_surgery import crafted, layout, rewrite, small_log  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    return small_log(tmp_path_factory.mktemp("clean") / "tiny.mcap")


@contextlib.contextmanager
def deadline(seconds: int, what: str):
    """Fail (instead of hanging the suite) if the block takes longer than ``seconds``."""

    def expired(_signum, _frame):
        raise TimeoutError(f"{what} took more than {seconds} s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def isaac(capsys, *argv) -> tuple[int, str, str]:
    with deadline(30, f"isaac {' '.join(map(str, argv))}"):
        status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def _commands(path: Path, clean: Path, tmp: Path) -> list[list]:
    return [
        ["inspect", path],
        ["inspect", path, "--step", 3],
        ["replay", path],
        ["replay", path, "--partial"],
        ["diff", clean, path],
        ["diff", path, clean],
        ["diff", path, path],
        ["recover", path, tmp / "recovered.mcap"],
    ]


def test_a_fifo_a_device_and_a_directory_are_refused_before_reading(clean, tmp_path, capsys):
    fifo = tmp_path / "run.mcap"
    os.mkfifo(fifo)
    folder = tmp_path / "folder.mcap"
    folder.mkdir()
    for path, kind in ((fifo, "a FIFO"), (folder, "a directory"), (Path("/dev/zero"), "device")):
        for argv in _commands(path, clean, tmp_path) + [["view", path, "--dry-run"]]:
            status, out, err = isaac(capsys, *argv)
            assert status == 2, (argv, out, err)
            assert "not a regular file" in err and kind in err and err.count("\n") == 1, err
    assert not (tmp_path / "recovered.mcap").exists()


def _malformed(clean: Path, tmp: Path) -> list[tuple[str, Path, str]]:
    """(name, crafted log, what the error must say): well-formed MCAP, malformed content."""

    def settings(value):
        return lambda meta: {**meta, "settings": value}

    def short_position(d):
        d["position"] = d["position"][:-1]

    def odd_vertices(d):
        d["bodies"][1]["vertices_local"] = d["bodies"][1]["vertices_local"][:-1]

    def body_999(d):
        d["b"] = np.array([999] + list(d["b"][1:]), dtype=np.uint32)

    return [
        ("settings []", rewrite(clean, tmp / "list.mcap", meta=settings("[]")), "settings are"),
        ("settings null", rewrite(clean, tmp / "null.mcap", meta=settings("null")), "settings"),
        (
            "settings deeply nested",
            rewrite(clean, tmp / "deep.mcap", meta=settings("[" * 100000 + "]" * 100000)),
            "metadata",
        ),
        ("dt not a number", rewrite(clean, tmp / "dt.mcap", meta=lambda m: {**m, "dt": "x"}), "dt"),
        (
            "a /bodies array one double short",
            rewrite(clean, tmp / "short.mcap", crafted("/bodies", 2, short_position)),
            "position holds 5 values for 3 bodies",
        ),
        (
            "odd-length /world vertices",
            rewrite(clean, tmp / "odd.mcap", crafted("/world", 0, odd_vertices)),
            "vertex coordinates",
        ),
        (
            "a contact naming body 999",
            rewrite(clean, tmp / "999.mcap", crafted("/contacts", 2, body_999)),
            "999",
        ),
    ]


def test_malformed_metadata_and_messages_are_damaged_log_errors(clean, tmp_path, capsys):
    for name, path, says in _malformed(clean, tmp_path):
        for argv in _commands(path, clean, tmp_path):
            status, out, err = isaac(capsys, *argv)
            assert status == 2, (name, argv, out, err)
            assert err.count("\n") == 1 and says in err, (name, argv, err)
            assert "Traceback" not in err
    assert not (tmp_path / "recovered.mcap").exists()


def _sparse(path: Path, clean: Path, *, compressed: bool) -> Path:
    """The clean log's header, then one chunk claiming 6 GiB, in a 6 GiB sparse file."""
    _, chunks = layout(clean)
    head = clean.read_bytes()[: chunks[0].record.start]
    size = 6 << 30
    with open(path, "wb") as f:
        f.write(head)
        if compressed:
            # a small zstd chunk record whose uncompressed size claims 6 GiB
            data = b"\x28\xb5\x2f\xfd" + bytes(60)
            fields = struct.pack("<QQQII", 0, 0, size, 0, 4) + b"zstd"
            body = fields + struct.pack("<Q", len(data)) + data
            f.write(struct.pack("<BQ", 0x06, len(body)) + body)
        else:
            length = size - len(head) - 9
            f.write(struct.pack("<BQ", 0x06, length))
            f.write(struct.pack("<QQQIIQ", 0, 0, length - 40, 0, 0, length - 40))
        f.truncate(size)
    return path


def _limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))


@pytest.mark.parametrize("compressed", [False, True], ids=["record", "uncompressed-size"])
def test_a_chunk_claiming_6_gib_is_refused_under_a_1_gib_limit(clean, tmp_path, compressed):
    assert MAX_RECORD_BYTES <= 1 << 30
    huge = _sparse(tmp_path / "huge.mcap", clean, compressed=compressed)
    commands = [["inspect", huge], ["replay", huge], ["recover", huge, tmp_path / "out.mcap"]]
    # the uncompressed-size check sits in the one chunk reader all three share: one suffices
    for argv in commands[:1] if compressed else commands:
        started = time.perf_counter()
        done = subprocess.run(
            [sys.executable, "-m", "isaac", *map(str, argv)],
            capture_output=True,
            text=True,
            cwd=REPO,
            preexec_fn=_limit_memory,
            timeout=60,
        )
        took = time.perf_counter() - started
        assert done.returncode == 2, (argv, done.stdout, done.stderr)
        assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr
        # where the clean log's first chunk began (its header and metadata come before it)
        at = layout(clean)[1][0].record.start
        assert "1 GiB" in done.stderr and f"byte {at}" in done.stderr, done.stderr
        assert took < 20, f"{argv[0]} took {took:.1f} s"
    assert not (tmp_path / "out.mcap").exists()


def _fuzzed(data: bytes, rng: np.random.Generator, starts: list[int]) -> bytes:
    """One random edit of a log's bytes: bytes changed, a cut, a crafted record inserted."""
    kind = int(rng.integers(4))
    b = bytearray(data)
    if kind == 0:  # a few bytes set to random values anywhere
        for _ in range(int(rng.integers(1, 9))):
            b[int(rng.integers(len(b)))] = int(rng.integers(256))
    elif kind == 1:  # cut anywhere
        b = b[: int(rng.integers(8, len(b)))]
    elif kind == 2:  # a record boundary overwritten: opcode and length random, some huge
        at = starts[int(rng.integers(len(starts)))]
        sizes = [0, 1, 8, 40, len(b), 1 << 32, 1 << 62, int(rng.integers(1 << 20))]
        length = int(rng.choice(sizes))
        struct.pack_into("<BQ", b, at, int(rng.integers(256)), length)
    else:  # a crafted record inserted between two others (any opcode, random body)
        at = starts[int(rng.integers(len(starts)))]
        body = rng.bytes(int(rng.integers(0, 64)))
        b[at:at] = struct.pack("<BQ", int(rng.integers(1, 16)), len(body)) + body
    return bytes(b)


_JSON = ["[]", "null", "1", '"x"', "{}", '{"dt": []}', "[{}]", "", "{", "1e999"]


def _crafted_content(clean: Path, rng: np.random.Generator, path: Path) -> None:
    """A well-formed log (every CRC and the summary agree) with one field of its content made
    wrong: an array cut, lengthened or emptied, an index or a scalar set out of range, or an
    ``isaac`` metadata value replaced by some other JSON."""
    if rng.integers(4) == 0:
        key = str(rng.choice(["settings", "dt", "gravity", "bodies", "format_version"]))
        value = str(rng.choice(_JSON))
        rewrite(clean, path, meta=lambda m: {**m, key: value})
        return
    topic = str(rng.choice(["/world", "/bodies", "/contacts", "/stats"]))
    step = 0 if topic == "/world" else int(rng.integers(0, 51))
    how = int(rng.integers(5))

    def change(d):
        target = d["bodies"][int(rng.integers(len(d["bodies"])))] if topic == "/world" else d
        arrays = [k for k, v in target.items() if isinstance(v, np.ndarray)]
        scalars = [k for k, v in target.items() if isinstance(v, (int, float)) and k != "step"]
        if how == 4 or not arrays:
            k = str(rng.choice(scalars))
            if isinstance(target[k], float):
                target[k] = float(rng.choice([0.0, -1.0, 1e308, np.inf, np.nan]))
            else:
                target[k] = int(rng.choice([0, 2**31, 2**32 - 1, 2**40]))
            return
        k = str(rng.choice(arrays))
        a = target[k]
        if how == 0:
            target[k] = a[:-1]
        elif how == 1:
            target[k] = np.concatenate([a, a[:1]])
        elif how == 2:
            target[k] = a[:0]
        else:
            a = a.copy()
            if a.size:
                a[int(rng.integers(a.size))] = 2**31 + 7 if a.dtype == np.uint32 else np.nan
            target[k] = a

    rewrite(clean, path, crafted(topic, step, change))


def test_fuzzed_logs_give_a_verdict_or_one_error_never_a_traceback(clean, tmp_path):
    data = clean.read_bytes()
    records, _ = layout(clean)
    starts = [r.start for r in records]
    rng = np.random.default_rng(5)
    bad = tmp_path / "fuzzed.mcap"
    started = time.perf_counter()
    outcomes: dict[str, int] = {}
    for case in range(300):
        if case % 4 == 3:
            _crafted_content(clean, rng, bad)
        else:
            bad.write_bytes(_fuzzed(data, rng, starts))
        with deadline(10, f"fuzz case {case}"):
            for what, run in (
                ("replay", lambda: replay_log(str(bad))),
                ("inspect", lambda: (LogReader(str(bad)).summary(), LogReader(str(bad)).world)),
                ("recover", lambda: recover(str(bad), str(tmp_path / "out.mcap"))),
                ("diff", lambda: diff_logs(str(clean), str(bad))),
            ):
                if what in ("recover", "diff") and case % 3:
                    continue  # a third of the cases go through every command
                try:
                    run()
                    outcome = "ran"
                except (LogError, SceneError) as exc:
                    assert "\n" not in str(exc), str(exc)
                    outcome = type(exc).__name__
                outcomes[f"{what} {outcome}"] = outcomes.get(f"{what} {outcome}", 0) + 1
    took = time.perf_counter() - started
    assert took < 60, f"300 fuzzed logs took {took:.1f} s"
    # the fuzz reached both ends: logs that still replay, logs that are refused
    assert outcomes.get("replay ran", 0) > 20 and outcomes.get("replay LogError", 0) > 20, outcomes
