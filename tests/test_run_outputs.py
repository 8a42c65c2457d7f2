"""`isaac run`'s output paths: every bad one is refused in one line with exit status 2 before
anything is written, and no earlier data is lost (the scene, the other output, an earlier
run's .partial, a run still writing the same file)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from close_gate import REPO, TINY_SCENE, held_in_close, isaac

from isaac.app.cli import main
from recorder.reader import LogReader

sys.path.insert(0, str(Path(__file__).parent / "recorder"))
from recorder_synth import SCENE_TEXT, SynthSim  # noqa: E402


@pytest.fixture
def scene(tmp_path) -> Path:
    path = tmp_path / "tiny.yaml"
    path.write_text(TINY_SCENE)
    return path


@pytest.fixture
def isaac_here(capsys):
    """`isaac ARGS...` in this process (the refusals come before any simulation: no need to
    pay a process start for each); returns what `isaac` (a subprocess) returns."""

    def run(*args):
        capsys.readouterr()
        status = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(args, status, out, err)

    return run


def _refused(result, *words: str) -> str:
    """The run was refused: exit 2, one line naming what is wrong, no traceback."""
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert "Traceback" not in result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("isaac run: error: "), result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


def _files(directory: Path) -> set[str]:
    return {p.name for p in directory.iterdir()}


# -- paths that cannot be written -----------------------------------------------------------


def _parent_is_a_file(tmp_path):
    (tmp_path / "notes.txt").write_text("a file")
    return tmp_path / "notes.txt" / "run.mcap", "notes.txt is not a directory"


def _ancestor_is_a_file(tmp_path):
    (tmp_path / "notes.txt").write_text("a file")
    return tmp_path / "notes.txt" / "sub" / "run.mcap", "notes.txt is not a directory"


def _parent_cannot_be_created(tmp_path):
    return Path("/proc/isaac-test-no-such-dir/run.mcap"), "cannot create /proc/isaac-test"


def _name_too_long(tmp_path):
    return tmp_path / ("x" * 300 + ".mcap"), "File name too long"


def _output_is_a_directory(tmp_path):
    (tmp_path / "out").mkdir()
    return tmp_path / "out", "it is a directory"


def _output_is_a_fifo(tmp_path):
    os.mkfifo(tmp_path / "run.mcap")
    return tmp_path / "run.mcap", "it is a FIFO"


def _partial_is_a_fifo(tmp_path):  # opening it for writing would wait for a reader for ever
    os.mkfifo(tmp_path / "run.mcap.partial")
    return tmp_path / "run.mcap", "run.mcap.partial: it is a FIFO"


def _partial_is_a_directory(tmp_path):
    (tmp_path / "run.mcap.partial").mkdir()
    return tmp_path / "run.mcap", "run.mcap.partial: Is a directory"


_UNWRITABLE = [
    _parent_is_a_file,
    _ancestor_is_a_file,
    _parent_cannot_be_created,
    _name_too_long,
    _output_is_a_directory,
    _partial_is_a_directory,
]


@pytest.mark.parametrize("case", _UNWRITABLE, ids=lambda f: f.__name__.lstrip("_"))
def test_an_output_that_cannot_be_written_is_refused_in_one_line(tmp_path, scene, case, isaac_here):
    out, why = case(tmp_path)
    before = _files(tmp_path)
    _refused(isaac_here("run", scene, "--quiet", "--mcap", out), why)
    assert _files(tmp_path) == before  # nothing created, nothing left behind


@pytest.mark.parametrize(
    "case, option",
    [(_output_is_a_fifo, "--mcap"), (_partial_is_a_fifo, "--rrd")],
    ids=["mcap-output", "rrd-partial"],
)
def test_a_fifo_for_an_output_is_refused_without_waiting(tmp_path, scene, case, option):
    out, why = case(tmp_path)
    if option == "--rrd":  # the same FIFO under the Rerun recording's name
        os.rename(tmp_path / "run.mcap.partial", tmp_path / "run.rrd.partial")
        out, why = tmp_path / "run.rrd", why.replace(".mcap", ".rrd")
    before = _files(tmp_path)
    # a subprocess with a time limit: opening a FIFO for writing waits for a reader
    _refused(isaac("run", scene, "--quiet", option, out, timeout=60), why)
    assert _files(tmp_path) == before


# -- outputs that are inputs or each other ----------------------------------------------------


def test_the_same_file_for_both_outputs_is_refused(tmp_path, scene, isaac_here):
    out = tmp_path / "run.out"
    _refused(isaac_here("run", scene, "--quiet", "--mcap", out, "--rrd", out), "--rrd", "--mcap")
    assert not out.exists() and not Path(str(out) + ".partial").exists()


def test_the_same_file_through_a_symlink_is_refused(tmp_path, scene, isaac_here):
    (tmp_path / "logs").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "logs")
    mcap, rrd = tmp_path / "link" / "run.mcap", tmp_path / "logs" / "run.mcap"
    _refused(isaac_here("run", scene, "--quiet", "--mcap", mcap, "--rrd", rrd), "same file")
    assert _files(tmp_path / "logs") == set()


@pytest.mark.parametrize("spelling", ["same path", "symlink", "hard link", "relative"])
def test_an_output_that_is_the_scene_is_refused_and_the_scene_kept(
    tmp_path, scene, spelling, isaac_here
):
    text = scene.read_bytes()
    if spelling == "same path":
        out = scene
    elif spelling == "symlink":
        out = tmp_path / "alias.yaml"
        out.symlink_to(scene)
    elif spelling == "hard link":
        out = tmp_path / "twin.yaml"
        os.link(scene, out)
    else:
        out = Path(os.path.relpath(scene))
    _refused(isaac_here("run", scene, "--quiet", "--mcap", out), "scene file")
    assert scene.read_bytes() == text


# -- an earlier run's .partial ----------------------------------------------------------------

_KILLED_RUN = r"""
import sys, time
sys.path.insert(0, {synth!r})
from recorder_synth import SynthSim, SCENE_TEXT
from recorder import Recorder

sim = SynthSim(6, 3)
rec = Recorder(sim, mcap_path={path!r}, scene_text=SCENE_TEXT, offload="none", flush_every=10)
rec.write(sim.record())
for _ in range(25):
    rec.write(sim.step())
print("recording", flush=True)
time.sleep(120)  # killed meanwhile, as a crashed run is
"""


def test_a_crashed_runs_partial_is_kept_until_forced_and_its_lock_died_with_it(
    tmp_path, scene, isaac_here
):
    path = tmp_path / "run.mcap"
    partial = Path(str(path) + ".partial")
    script = _KILLED_RUN.format(synth=str(Path(__file__).parent / "recorder"), path=str(path))
    crashed = subprocess.Popen([sys.executable, "-c", script], cwd=REPO, stdout=subprocess.PIPE)
    try:
        assert crashed.stdout.readline() == b"recording\n"
        # while it runs, no other run takes its file, --force or not
        for force in ((), ("--force",)):
            result = isaac_here("run", scene, "--quiet", "--mcap", path, *force)
            _refused(result, "being written by another")
    finally:
        crashed.send_signal(signal.SIGKILL)
        crashed.wait()
    kept = partial.read_bytes()
    # flushed after steps 0, 9 and 19: 20 steps to recover; the lock died with the process
    line = _refused(isaac_here("run", scene, "--quiet", "--mcap", path), "holds 20 steps")
    assert f"isaac recover {partial} " in line and "--force" in line
    assert partial.read_bytes() == kept  # byte for byte
    assert not path.exists()
    result = isaac_here("run", scene, "--quiet", "--steps", 12, "--mcap", path, "--force")
    assert result.returncode == 0, result.stderr
    assert not partial.exists()
    assert [s.step for s in LogReader(str(path)).steps()] == list(range(13))


def test_an_earlier_runs_rrd_partial_with_steps_is_kept(tmp_path, scene, isaac_here):
    from recorder import Recorder

    sim = SynthSim(4, 2)
    rec = Recorder(sim, rrd_path=str(tmp_path / "old.rrd"), scene_text=SCENE_TEXT, offload="none")
    rec.write(sim.record())
    for _ in range(9):
        rec.write(sim.step())
    rec.close()
    partial = tmp_path / "run.rrd.partial"
    os.rename(tmp_path / "old.rrd", partial)
    kept = partial.read_bytes()
    _refused(isaac_here("run", scene, "--quiet", "--rrd", tmp_path / "run.rrd"), "holds 10 steps")
    assert partial.read_bytes() == kept


@pytest.mark.parametrize("content", ["empty", "header only"])
def test_a_partial_that_holds_no_step_is_replaced(tmp_path, content):
    from recorder.mcap_writer import McapLogWriter
    from recorder.outputs import claim

    path = tmp_path / "run.mcap"
    if content == "empty":
        Path(str(path) + ".partial").write_bytes(b"")
    else:  # what a run killed before its first step leaves
        sim = SynthSim(4, 2)
        McapLogWriter(str(path), sim.model, sim.scene, SCENE_TEXT).abandon()
        assert Path(str(path) + ".partial").stat().st_size > 0
    claim(str(path), "mcap").release()


# -- two runs, one file -----------------------------------------------------------------------


def test_a_second_run_to_the_same_file_is_refused_while_the_first_runs(tmp_path, scene, isaac_here):
    path = tmp_path / "run.mcap"
    first_args = ("run", scene, "--quiet", "--steps", 30, "--mcap", path)
    with held_in_close(tmp_path, *first_args) as first:  # the first run is finishing its file
        for force in ((), ("--force",)):
            second = isaac_here("run", scene, "--quiet", "--steps", 7, "--mcap", path, *force)
            _refused(second, "run.mcap.partial is being written by another run")
        status = first.release()
    assert status == 0, first.err
    assert [s.step for s in LogReader(str(path)).steps()] == list(range(31))  # the first's
    assert not Path(str(path) + ".partial").exists()
