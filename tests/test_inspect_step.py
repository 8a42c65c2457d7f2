"""`isaac inspect LOG --step K`: one body's contacts (--body), the rows as CSV or JSON
(--format) with the logged values exactly, and a step the log does not hold named with the range
it does."""

from __future__ import annotations

import csv
import io
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENE = """
world: {fidelity: balanced, steps: 20}
bodies:
  - {name: ground, shape: {box: [10, 1]}, concrete: true}
  - {name: left, shape: {box: [1, 1]}, position: [-1, 0.95]}
  - {name: right, shape: {box: [1, 1]}, position: [1, 0.95]}
"""


def _isaac(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "isaac", *args], cwd=ROOT, capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("inspect")
    (folder / "two.yaml").write_text(SCENE)
    out = folder / "two.mcap"
    done = _isaac("run", str(folder / "two.yaml"), "--mcap", str(out), "--quiet")
    assert done.returncode == 0, done.stderr
    return out


def test_body_filter_keeps_only_that_bodys_contacts(log):
    from recorder.reader import LogReader

    c = LogReader(str(log)).step(10).record.contacts
    left = 1
    expected = [i for i in range(len(c)) if left in (int(c.a[i]), int(c.b[i]))]
    assert 0 < len(expected) < len(c)  # ground touches both boxes: the filter drops some rows
    done = _isaac("inspect", str(log), "--step", "10", "--body", "left", "--format", "csv")
    assert done.returncode == 0, done.stderr
    rows = list(csv.reader(io.StringIO(done.stdout)))
    assert rows[0][:4] == ["row", "sub", "a", "b"]
    assert [int(r[0]) for r in rows[1:]] == expected
    assert all("1:left" in (r[2], r[3]) for r in rows[1:])


def test_json_carries_the_logged_values_exactly(log):
    from recorder.reader import LogReader

    logged = LogReader(str(log)).step(10)
    done = _isaac("inspect", str(log), "--step", "10", "--format", "json")
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    assert got["step"] == 10 and got["bodies"]["name"] == ["ground", "left", "right"]
    assert got["bodies"]["position_m"] == logged.record.position.tolist()
    assert got["contacts"]["impulse_Ns"] == logged.record.contacts.impulse.tolist()
    assert got["stats"]["state_hash"] == logged.stats["state_hash"]


def test_a_step_or_body_the_log_lacks_is_one_line_naming_what_it_holds(log):
    done = _isaac("inspect", str(log), "--step", "999")
    assert done.returncode == 2
    assert done.stderr.strip().endswith("step 999 is not in the log (it holds steps 0..20)")
    done = _isaac("inspect", str(log), "--step", "3", "--body", "lft")
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1
    assert "no body named 'lft' in the log (did you mean 'left'?)" in done.stderr
