"""A long `isaac run --mcap` says first how large its log will be (uncompressed), and the
estimate is close to what it writes."""

from __future__ import annotations

import re
import subprocess
import sys

UNITS = {"bytes": 1, "KiB": 2**10, "MiB": 2**20, "GiB": 2**30}


def test_a_recorded_run_first_says_how_large_its_log_will_be(tmp_path):
    out = tmp_path / "pile.mcap"
    run = subprocess.run(
        [sys.executable, "-m", "isaac", "run", "scenes/pile.yaml", "--steps", "600", "--quiet",
         "--mcap", str(out), "--compression", "none"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    said = re.search(r"expected MCAP log size: about ([\d.]+) (\w+) \(", run.stderr)
    assert said, run.stderr
    expected = float(said.group(1)) * UNITS[said.group(2)]
    assert 0.75 < expected / out.stat().st_size < 1.33


def test_a_short_run_or_one_without_a_log_says_nothing_of_its_size(tmp_path):
    for extra in ([], ["--mcap", str(tmp_path / "short.mcap")]):
        run = subprocess.run(
            [sys.executable, "-m", "isaac", "run", "scenes/stack.yaml", "--steps", "5",
             "--quiet", *extra],
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert run.returncode == 0 and "log size" not in run.stderr + run.stdout
