"""`offload="auto"`: writer processes only where the machine has idle CPUs for them."""

from __future__ import annotations

import subprocess
import sys

import pytest

from recorder.writer_process import choose_offload


@pytest.mark.parametrize(
    ("writers", "cpus", "load", "expected", "log_bytes"),
    [
        (1, 2, 0.2, "process", None),  # an idle 2-core machine: one writer has a CPU of its own
        (2, 2, 0.2, "thread", None),  # two writers and the simulation do not fit on 2 CPUs
        (1, 2, 3.0, "thread", None),  # two other busy processes: no idle CPU
        (2, 8, 2.0, "process", None),
        (2, 8, 7.5, "thread", None),
        (1, 1, 0.0, "thread", None),
        (1, 8, 0.0, "thread", 10_000_000),  # a short run: writer processes take seconds to start
        (1, 8, 0.0, "process", 500_000_000),
    ],
)
def test_auto_takes_processes_only_with_an_idle_cpu_for_each_writer_on_a_long_run(
    writers, cpus, load, expected, log_bytes
):
    assert choose_offload(writers, cpus=cpus, load=load, log_bytes=log_bytes) == expected


@pytest.mark.parametrize("offload", ["auto", "process", "thread", "none"])
def test_every_offload_of_isaac_run_writes_the_same_log(tmp_path, offload):
    out = tmp_path / f"{offload}.mcap"
    run = subprocess.run(
        [sys.executable, "-m", "isaac", "run", "scenes/stack.yaml", "--steps", "40", "--quiet",
         "--mcap", str(out), "--offload", offload],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    written = run.stdout.split("written by offload ")[1].split()[0]
    assert written == offload if offload != "auto" else written in ("process", "thread")
    reference = tmp_path / "none.mcap"
    if offload != "none":
        subprocess.run(
            [sys.executable, "-m", "isaac", "run", "scenes/stack.yaml", "--steps", "40",
             "--quiet", "--mcap", str(reference), "--offload", "none"],
            check=True, capture_output=True, timeout=300,
        )  # fmt: skip
    assert out.read_bytes() == reference.read_bytes()


@pytest.mark.parametrize("compression", ["lz4", "zstd"])
def test_a_compressed_log_is_smaller_and_replays_identical(tmp_path, compression):
    plain, packed = tmp_path / "none.mcap", tmp_path / f"{compression}.mcap"
    for out, c in ((plain, "none"), (packed, compression)):
        subprocess.run(
            [sys.executable, "-m", "isaac", "run", "scenes/default.yaml", "--steps", "60",
             "--quiet", "--mcap", str(out), "--compression", c],
            check=True, capture_output=True, timeout=300,
        )  # fmt: skip
    assert packed.stat().st_size < 0.75 * plain.stat().st_size
    replay = subprocess.run(
        [sys.executable, "-m", "isaac", "replay", str(packed)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert replay.returncode == 0 and replay.stdout.startswith("identical"), replay.stdout
