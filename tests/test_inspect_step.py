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
    assert rows[0][:5] == ["row", "m", "sub", "a", "b"]
    assert [int(r[0]) for r in rows[1:]] == expected
    assert all("1:left" in (r[3], r[4]) for r in rows[1:])
    # a manifold's rows name one manifold; its pair depth is its own, the points' depths theirs
    head = rows[0]
    m, pair, point = head.index("m"), head.index("pair_depth"), head.index("point_depth")
    for r in rows[1:]:
        i = int(r[0])
        assert float(r[pair]) == pytest.approx(c.pair_depth[i], rel=1e-5, abs=1e-12)
        assert float(r[point]) == pytest.approx(c.depth[i], rel=1e-5, abs=1e-12)
    assert len({r[m] for r in rows[1:]}) < len(rows) - 1  # two points share a manifold


def test_json_carries_the_logged_values_exactly(log):
    from recorder.reader import LogReader

    logged = LogReader(str(log)).step(10)
    done = _isaac("inspect", str(log), "--step", "10", "--format", "json")
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout)
    assert got["step"] == 10 and got["bodies"]["name"] == ["ground", "left", "right"]
    assert got["bodies"]["position_m"] == logged.record.position.tolist()
    c = logged.record.contacts
    assert got["contacts"]["impulse_Ns"] == c.impulse.tolist()
    assert got["contacts"]["pair_depth_m"] == c.pair_depth.tolist()
    assert got["contacts"]["point_depth_m"] == c.depth.tolist()
    assert got["contacts"]["manifold"][-1] == int((c.slot == 0).sum()) - 1
    assert got["stats"]["state_hash"] == logged.stats["state_hash"]


def test_a_step_or_body_the_log_lacks_is_one_line_naming_what_it_holds(log):
    done = _isaac("inspect", str(log), "--step", "999")
    assert done.returncode == 2
    assert done.stderr.strip().endswith("step 999 is not in the log (it holds steps 0..20)")
    done = _isaac("inspect", str(log), "--step", "3", "--body", "lft")
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1
    assert "no body named 'lft' in the log (did you mean 'left'?)" in done.stderr
