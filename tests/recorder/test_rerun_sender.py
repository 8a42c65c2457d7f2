"""The Rerun sender process (recorder.rerun_send, recorder.writer_process.RerunSendProcess):
the same .rrd entity data and MCAP bytes as writing in-process, no process left behind, and a
failed or abandoned run closes or keeps its files by the usual rules."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import uuid
from pathlib import Path

import pytest

from isaac.errors import LogError, SimulationError
from recorder import Recorder
from recorder.spawn import SENDER, start_sender_child

sys.path.insert(0, str(Path(__file__).parent))
from recorder_synth import SCENE_TEXT  # noqa: E402
from test_writer_process import _records, _rrd_content, _with_value  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


def _rrd_notes(path) -> tuple[set[int], list[str]]:
    """(steps with contact points, warning texts) of a .rrd (or its .partial)."""
    from rerun.chunk import RrdReader

    steps, notes = set(), []
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/world/contacts" and "Points2D:positions" in batch.schema.names:
            steps.update(batch.column("step").to_pylist())
        if chunk.entity_path == "/log" and "TextLog:text" in batch.schema.names:
            notes += [text for row in batch.column("TextLog:text").to_pylist() for text in row]
    return steps, notes


def test_the_sender_process_writes_the_rrd_and_mcap_that_writing_in_process_does(tmp_path):
    """250 steps (three batches sent, bodies leaving at step 40): the same entity data in the
    .rrd, the same MCAP bytes, and the sender has exited once the recorder is closed."""
    sim, records = _records(n=30, contacts=20, steps=250, leave_at=40)
    out, child = {}, None
    for label in ("in-process", "sender"):
        mcap, rrd = tmp_path / f"{label}.mcap", tmp_path / f"{label}.rrd"
        children = {"rrd": start_sender_child()} if label == "sender" else {}
        child = children.get("rrd", child)
        rec = Recorder(
            sim,
            mcap_path=str(mcap),
            rrd_path=str(rrd),
            scene_text=SCENE_TEXT,
            compression="none",
            offload="thread" if children else "none",
            children=children,
        )
        assert rec.offload == ("thread (rrd: sender process)" if children else "none")
        for r in records:
            rec.write(r)
        rec.close()
        out[label] = (mcap.read_bytes(), _rrd_content(rrd))
    assert child.kind == SENDER and child.proc.poll() == 0  # exited, cleanly
    assert out["sender"][0] == out["in-process"][0]
    a, b = out["in-process"][1], out["sender"][1]
    assert sorted(a) == sorted(b)
    for key, columns in a.items():
        assert all(values.equals(b[key][name]) for name, values in columns.items()), key
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "in-process.mcap",
        "in-process.rrd",
        "sender.mcap",
        "sender.rrd",
    ]


def test_a_nan_stops_the_run_and_the_sender_still_finishes_the_file(tmp_path):
    """A record holding a NaN raises SimulationError; closing as `isaac run` does then keeps
    every earlier step, notes where the run stopped, renames the file and ends the child."""
    sim, records = _records(n=12, contacts=6, steps=150)
    child = start_sender_child()
    path = tmp_path / "nan.rrd"
    rec = Recorder(
        sim, rrd_path=str(path), scene_text=SCENE_TEXT, offload="thread", children={"rrd": child}
    )
    for r in records[:131]:
        rec.write(r)
    with pytest.raises(SimulationError, match="step 131"):
        rec.write(_with_value(records[131], "position", float("nan")))
    rec.close(complete=False, reason="step 131: a recorded value is not finite")
    assert child.proc.poll() == 0
    assert not Path(str(path) + ".partial").exists()
    steps, notes = _rrd_notes(path)
    assert steps == set(range(131))
    assert any("run stopped at step 130" in str(n) for n in notes), notes


def test_a_sender_the_recorder_cannot_use_exits_and_writes_nothing(tmp_path):
    sim, _ = _records(n=4, contacts=2, steps=1)
    child = start_sender_child()
    same = str(tmp_path / "same")
    with pytest.raises(LogError):
        Recorder(sim, mcap_path=same, rrd_path=same, scene_text=SCENE_TEXT, children={"rrd": child})
    assert child.proc.poll() == 0
    assert list(tmp_path.iterdir()) == []


_DIES = """
import os, sys
sys.path[:0] = [{repo!r}, {here!r}]
from recorder import Recorder
from recorder.spawn import start_sender_child
from recorder_synth import SCENE_TEXT
from test_writer_process import _records

sim, records = _records(n=12, contacts=6, steps=250)
child = start_sender_child()
rec = Recorder(sim, rrd_path={path!r}, scene_text=SCENE_TEXT, offload="thread",
               children={{"rrd": child}})
for r in records[:231]:  # steps 0-199 sent as two batches, 200-230 still in the open one
    rec.write(r)
rec.rerun._sender._queue.join()  # both batches written to the pipe
print(child.proc.pid, flush=True)
os.kill(os.getpid(), 9)
"""


def test_a_sender_whose_run_died_keeps_every_batch_it_was_sent_in_the_partial(tmp_path):
    """The run is killed (SIGKILL): the child writes out the batches it was sent, notes that
    the run was abandoned and keeps the .partial (`isaac recover` is for MCAP; the recording
    is for looking). The steps of the batch still open in the dead process are lost."""
    path = tmp_path / "orphan.rrd"
    code = _DIES.format(repo=str(REPO), here=str(Path(__file__).parent), path=str(path))
    run = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300
    )
    assert run.returncode == -9, run.stderr
    pid = int(run.stdout.split()[0])
    for _ in range(600):  # the orphan finishes on its own
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        import time

        time.sleep(0.1)
    else:
        pytest.fail("the sender process did not exit after its run died")
    partial = Path(str(path) + ".partial")
    assert partial.exists() and not path.exists()
    steps, notes = _rrd_notes(partial)
    assert steps == set(range(200))
    assert any(str(n).startswith("abandoned") for n in notes), notes


def _processes_tagged(tag: str) -> list[int]:
    """Processes whose environment holds ``tag`` (this machine's /proc)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/environ", "rb") as f:
                if tag.encode() in f.read():
                    found.append(int(entry))
        except OSError:
            continue
    return found


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs /proc")
@pytest.mark.parametrize("offload", ["auto", "thread"])
def test_isaac_run_sends_the_rrd_from_a_process_that_is_gone_when_it_returns(tmp_path, offload):
    tag = f"ISAAC_TEST_TAG={uuid.uuid4().hex}"
    env = {**os.environ, tag.split("=")[0]: tag.split("=")[1]}
    mcap, rrd = tmp_path / "run.mcap", tmp_path / "run.rrd"
    run = subprocess.run(
        [sys.executable, "-m", "isaac", "run", "scenes/head_on.yaml", "--steps", "150",
         "--quiet", "--mcap", str(mcap), "--rrd", str(rrd), "--offload", offload],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    assert "written by offload thread (rrd: sender process)" in run.stdout
    assert _processes_tagged(tag) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap", "run.rrd"]
    steps, notes = _rrd_notes(rrd)
    assert notes == []
    reference = tmp_path / "ref.rrd"
    subprocess.run(
        [sys.executable, "-m", "isaac", "run", "scenes/head_on.yaml", "--steps", "150",
         "--quiet", "--rrd", str(reference), "--offload", "none"],
        cwd=REPO, check=True, capture_output=True, timeout=300,
    )  # fmt: skip
    a, b = _rrd_content(reference), _rrd_content(rrd)
    assert sorted(a) == sorted(b)
    for key, columns in a.items():
        assert all(values.equals(b[key][name]) for name, values in columns.items()), key


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs /proc")
def test_a_bad_scene_read_after_the_sender_started_leaves_no_file_and_no_process(tmp_path):
    """`isaac run` starts the sender before it reads the scene: a scene it then refuses exits
    2 with one line naming file, line and key, and the sender, both outputs and the
    directories made for them are gone (a directory that was there stays)."""
    tag = f"ISAAC_TEST_TAG={uuid.uuid4().hex}"
    env = {**os.environ, tag.split("=")[0]: tag.split("=")[1]}
    scene = tmp_path / "bad.yaml"
    scene.write_text("world:\n  dt: -1\nbodies: []\n")
    out = tmp_path / "out"
    run = subprocess.run(
        [sys.executable, "-m", "isaac", "run", str(scene), "--quiet",
         "--mcap", str(out / "run.mcap"), "--rrd", str(out / "deeper" / "run.rrd")],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 2
    assert run.stderr.strip().splitlines() == [
        f"isaac run: error: {scene}:2: world.dt: -1 is out of range (must be > 0.0 and <= 1.0)"
    ]
    assert _processes_tagged(tag) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.yaml"]
