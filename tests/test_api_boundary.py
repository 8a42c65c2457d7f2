"""The Python API's boundary: what a caller hands a `Simulation` (a record to resume from, the
state's arrays, a count of steps) is refused with one clear exception before compiled code
sees it (`isaac.engine.guards`, docs/physics.md "The Python API's guards").

A record of another scene crossed into the compiled kernels unchecked: 3 bodies into 2
segfaulted, 2 into 3 aborted with "corrupted size vs. prev_size". The cases that could kill
the interpreter run in one child process (`hostile_outcomes`), so that a crash fails these
tests instead of ending pytest.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest
from api_hostile import HOSTILE_SCENES, ROOT, built, in_child, record_of, scene, scene_text

from isaac.engine.records import StepRecord, state_hash
from isaac.engine.simulation import Simulation
from isaac.errors import StateError
from isaac.scene import load_scene


def _replaced(record: StepRecord, **fields) -> StepRecord:
    return dataclasses.replace(record, **fields)


def _contacts(record: StepRecord, **fields):
    return _replaced(record, contacts=dataclasses.replace(record.contacts, **fields))


def _joints(record: StepRecord, **fields):
    return _replaced(record, joints=dataclasses.replace(record.joints, **fields))


def _assigned(field, value_of):
    """A hostile call: the state's `field` replaced between steps, then a step."""

    def call(sim):
        setattr(sim.state, field, value_of(getattr(sim.state, field)))
        sim.step()

    return call


def _first(a):
    b = np.array(a)
    b[0] = np.nan
    return b


# name: (scene of the simulation, the hostile call, the exception, words its message holds)
HOSTILE = {
    "3 bodies into 2": (
        (2,),
        lambda sim: sim.resume(record_of(3)),
        StateError,
        "holds 3 bodies; the scene has 2",
    ),
    "1 body into 3": (
        (3,),
        lambda sim: sim.resume(record_of(1)),
        StateError,
        "holds 1 bodies; the scene has 3",
    ),
    "4 bodies into 1": (
        (1,),
        lambda sim: sim.resume(record_of(4)),
        StateError,
        "holds 4 bodies; the scene has 1",
    ),
    "1 joint into none": (
        (3,),
        lambda sim: sim.resume(record_of(3, joints=1)),
        StateError,
        "the record has 1 joints, the scene has 0",
    ),
    "1 joint into 2": (
        (4, 2),
        lambda sim: sim.resume(record_of(4, joints=1)),
        StateError,
        "the record has 1 joints, the scene has 2",
    ),
    "another dt": (
        (3,),
        lambda sim: sim.resume(record_of(3, dt="0.02")),
        StateError,
        "the record's time is 0.1 s at step 5",
    ),
    "another body entering": (
        (3,),
        lambda sim: sim.resume(record_of(3, enters=1.0)),
        StateError,
        "body 'box2' (index 2) does not exist at step 5",
    ),
    "NaN velocity": (
        (3,),
        lambda sim: sim.resume(_replaced(record_of(3), velocity=_first(record_of(3).velocity))),
        StateError,
        "velocity of body 'floor' (index 0) is not finite",
    ),
    "position of 3 columns": (
        (3,),
        lambda sim: sim.resume(_replaced(record_of(3), position=np.zeros((3, 3)))),
        StateError,
        "position has shape (3, 3); it must be (3, 2)",
    ),
    "exists as floats": (
        (3,),
        lambda sim: sim.resume(_replaced(record_of(3), exists=np.ones(3))),
        StateError,
        "exists has dtype float64; it must be bool",
    ),
    "step 2.5": (
        (3,),
        lambda sim: sim.resume(_replaced(record_of(3), step=2.5)),
        TypeError,
        "the record's step must be an int >= 0, got 2.5",
    ),
    "contact naming body 3 of 3": (
        (3,),
        lambda sim: sim.resume(_contacts(r := record_of(3), b=np.full(len(r.contacts), 3))),
        StateError,
        "has b 3, outside 0..2 (the scene has 3 bodies)",
    ),
    "contact rows out of order": (
        (3,),
        lambda sim: sim.resume(
            _contacts(r := record_of(3), a=r.contacts.a[::-1].copy(), b=r.contacts.b[::-1].copy())
        ),
        StateError,
        "not after the one before it in (substep, a, b, slot) order",
    ),
    "contacts of unequal lengths": (
        (3,),
        lambda sim: sim.resume(_contacts(r := record_of(3), impulse=r.contacts.impulse[:-1])),
        StateError,
        "the record's contacts.impulse has shape",
    ),
    "infinite impulse": (
        (3,),
        lambda sim: sim.resume(
            _contacts(r := record_of(3), impulse=np.full(len(r.contacts), np.inf))
        ),
        StateError,
        "contacts.impulse of row 0 is not finite",
    ),
    "joint impulses of 5 columns": (
        (3, 1),
        lambda sim: sim.resume(_joints(record_of(3, joints=1), impulses=np.zeros((1, 5)))),
        StateError,
        "joints.impulses has shape (1, 5); it must be (1, 6)",
    ),
    "start=42": ((3,), lambda sim: Simulation(sim.scene, start=42), TypeError, "got int"),
    "start=a Simulation": (
        (3,),
        lambda sim: Simulation(sim.scene, start=sim),
        TypeError,
        "must be a StepRecord, got Simulation",
    ),
    "position of 4 bodies assigned": (
        (3,),
        _assigned("position", lambda a: np.zeros((4, 2))),
        StateError,
        "sim.state.position holds 4 bodies; the scene has 3",
    ),
    "angle as float32 assigned": (
        (3,),
        _assigned("angle", lambda a: a.astype(np.float32)),
        StateError,
        "sim.state.angle has dtype float32",
    ),
    "velocity not contiguous assigned": (
        (3,),
        _assigned("velocity", lambda a: np.zeros((3, 4))[:, ::2]),
        StateError,
        "sim.state.velocity is not C-contiguous",
    ),
    "a batch record's read-only position assigned": (
        (3,),
        lambda sim: _assigned("position", lambda a: next(sim.run(1)).position)(sim),
        StateError,
        "sim.state.position is read-only",
    ),
    "NaN angular velocity assigned": (
        (3,),
        _assigned("angular_velocity", _first),
        StateError,
        "sim.state.angular_velocity of body 'floor' (index 0) is not finite",
    ),
    "exists as a list assigned": (
        (3,),
        _assigned("exists", lambda a: [True] * 3),
        TypeError,
        "sim.state.exists must be a numpy array, got list",
    ),
    "state replaced by None": (
        (3,),
        lambda sim: (setattr(sim, "state", None), sim.advance(2)),
        TypeError,
        "sim.state must be an isaac.engine.world.State",
    ),
    "step index 2.5 assigned": (
        (3,),
        lambda sim: (setattr(sim.state, "step", 2.5), sim.step()),
        TypeError,
        "sim.state.step must be an int >= 0, got 2.5",
    ),
    "position of 2 bodies assigned, then run": (
        (3,),
        lambda sim: (setattr(sim.state, "position", np.zeros((2, 2))), list(sim.run(3))),
        StateError,
        "holds 2 bodies; the scene has 3",
    ),
    "velocity of 1 body assigned, then detect": (
        (3,),
        lambda sim: (setattr(sim.state, "velocity", np.zeros((1, 2))), sim.detect()),
        StateError,
        "holds 1 bodies; the scene has 3",
    ),
}


def run_cases(names) -> None:
    """The child: each named case on a simulation stepped 3 times (the driver's path, then
    the staged one), printing one JSON line per case as it ends (flushed, so that the parent
    knows which case a crash ended on)."""
    for name in names:
        (n, *joints), call, _, _ = HOSTILE[name]
        for staged in (False, True):
            sim = Simulation(scene(n, joints=joints[0] if joints else 0), staged=staged)
            for _ in range(3):
                sim.step()
            try:
                call(sim)
                outcome = {"raised": None}
            except Exception as exc:  # noqa: BLE001  (the parent checks which)
                outcome = {"raised": type(exc).__name__, "message": str(exc)}
            print(json.dumps({"case": name, "staged": staged, **outcome}), flush=True)


@pytest.fixture(scope="module")
def hostile_outcomes() -> dict:
    """Every HOSTILE case's outcome, from one child process; a crash fails every case not
    reported, naming the case it died in and how."""
    code = f"import test_api_boundary as t; t.run_cases({list(HOSTILE)!r})"
    child = in_child(code)
    outcomes = {}
    for line in child.stdout.splitlines():
        got = json.loads(line)
        outcomes[got["case"], got["staged"]] = got
    outcomes["child"] = child
    return outcomes


@pytest.mark.parametrize("staged", [False, True], ids=["driver", "staged"])
@pytest.mark.parametrize("name", list(HOSTILE))
def test_a_hostile_record_or_state_array_is_refused_with_a_message_naming_what_differs(
    hostile_outcomes, name, staged
):
    child = hostile_outcomes["child"]
    got = hostile_outcomes.get((name, staged))
    assert got is not None, (
        f"the child died (exit status {child.returncode}) before reporting {name!r}:\n"
        + "\n".join(child.stderr.splitlines()[-15:])
    )
    _, _, kind, words = HOSTILE[name]
    assert got["raised"] == kind.__name__, got
    assert words in got["message"], got["message"]
    assert "\n" not in got["message"]


def test_a_refused_record_leaves_the_simulation_where_it_was():
    sim, fresh = Simulation(scene(3)), Simulation(scene(3))
    for s in (sim, fresh):
        for _ in range(4):
            s.step()
    bad = _replaced(record_of(3), position=np.zeros((3, 3)))
    with pytest.raises(StateError):
        sim.resume(bad)
    assert state_hash(sim.step()) == state_hash(fresh.step())


def test_a_record_is_copied_on_resume_so_changing_it_later_changes_nothing():
    sim = Simulation(scene(3))
    records = [sim.step() for _ in range(8)]
    mine = dataclasses.replace(
        records[3],
        velocity=records[3].velocity.copy(),
        contacts=dataclasses.replace(records[3].contacts, b=records[3].contacts.b.copy()),
    )
    resumed = Simulation(scene(3), start=mine)
    mine.velocity[:] = 1e3  # after the resume: not the simulation's any more
    mine.contacts.b[:] = 99
    got = [resumed.step() for _ in range(4)]
    assert [state_hash(r) for r in got] == [state_hash(r) for r in records[4:]]


SHIPPED = ["stack", "double_pendulum", "spawn", "car", "newton_cradle", "filtering"]


@pytest.mark.parametrize("name", SHIPPED)
def test_every_record_a_simulation_makes_resumes_to_the_same_bits(name):
    """The guards refuse nothing the engine makes: a record from `step()`, from `run`'s
    batches (read-only views) and from `record()` after `advance`, each resumed, goes on to the
    bits of the run that went through it."""
    scene_ = load_scene(ROOT / "scenes" / f"{name}.yaml")
    sim = Simulation(scene_)
    made = [sim.step() for _ in range(12)]
    made += list(sim.run(12, batch=5))
    sim.advance(7)
    made.append(sim.record())
    after = [sim.step() for _ in range(2)]
    assert any(len(r.contacts) for r in made) or made[0].joints is not None  # (rows to carry)
    for i in (5, 17, len(made) - 1):
        resumed = Simulation(scene_, start=made[i])
        want = made[i + 1 : i + 3] if i + 3 <= len(made) else after
        assert [state_hash(resumed.step()) for _ in want] == [state_hash(r) for r in want]


# ---- counts: one validator (isaac.engine.counts.count) for every call taking one


def _sim():
    return Simulation(scene(3))


@pytest.mark.parametrize(
    "call",
    [
        lambda s: s.advance(1.5),
        lambda s: s.advance(True),
        lambda s: s.advance("3"),
        lambda s: s.run(2.5),
        lambda s: s.run(3, batch=2.0),
        lambda s: s.batches(np.float64(4)),
        lambda s: s.batches(4, size=None),
        lambda s: s.batches(4, size=np.bool_(True)),
    ],
    ids=[
        "advance 1.5", "advance True", "advance '3'", "run 2.5", "run batch 2.0",
        "batches 4.0", "batches size None", "batches size np.True_",
    ],
)  # fmt: skip
def test_a_count_that_is_not_an_int_is_a_type_error_and_takes_no_step(call):
    sim = _sim()
    with pytest.raises(TypeError, match="must be an int"):
        call(sim)
    assert sim.step_index == 0 and sim.record().step == 0


def test_a_place_in_a_batch_that_is_not_an_int_is_a_type_error():
    batch = next(_sim().batches(2))
    for call in (batch.record, batch.contacts_of, batch.joints_of):
        with pytest.raises(TypeError, match="a batch's place must be an int"):
            call(1.0)


@pytest.mark.parametrize(
    "call",
    [
        lambda s: s.advance(-5),
        lambda s: s.run(-3),
        lambda s: s.batches(-1),
        lambda s: s.run(3, batch=0),
        lambda s: s.batches(3, size=0),
        lambda s: s.advance(1 << 63),
        lambda s: next(s.batches(2)).record(-1),
        lambda s: next(s.batches(2)).record(2),
        lambda s: next(s.batches(2)).contacts_of(-1),
        lambda s: next(s.batches(2)).joints_of(5),
    ],
    ids=[
        "advance -5", "run -3", "batches -1", "run batch 0", "batches size 0", "advance 2^63",
        "batch place -1", "batch place 2 of 2", "contacts of place -1", "joints of place 5",
    ],
)  # fmt: skip
def test_a_count_out_of_range_is_a_value_error_raised_at_the_call(call):
    sim = _sim()
    with pytest.raises(ValueError, match="must be an int from|past the batch's last"):
        call(sim)
    assert sim.step_index in (0, 2)


def test_run_checks_its_counts_when_called_not_when_iterated():
    sim = _sim()
    with pytest.raises(ValueError):
        sim.run(-3)  # never iterated
    with pytest.raises(TypeError):
        sim.batches(2.5)


def test_numpy_integers_are_counts_and_records_keep_integer_steps():
    sim = _sim()
    sim.advance(np.int64(3))
    got = list(sim.run(np.int32(4), batch=np.uint8(3)))
    batch = next(sim.batches(np.int16(2), size=np.int64(2)))
    steps = [r.step for r in got] + [batch.record(np.int64(1)).step, sim.step_index]
    assert steps == [4, 5, 6, 7, 9, 9]
    assert all(type(s) is int for s in steps)
    assert [r.time for r in got] == [s * 0.01 for s in (4, 5, 6, 7)]


def test_zero_steps_do_nothing_in_every_call():
    sim = _sim()
    sim.advance(0)
    assert list(sim.run(0)) == [] and list(sim.batches(0)) == [] and sim.step_index == 0


def test_the_cli_refuses_a_negative_or_fractional_step_option_in_one_line(tmp_path):
    log = ROOT / "tests" / "fixtures" / "golden" / "head_on.mcap"
    (tmp_path / "s.yaml").write_text(scene_text(2))
    isaac = [sys.executable, "-m", "isaac"]
    for argv in (
        ["run", str(tmp_path / "s.yaml"), "--steps", "-3"],
        ["replay", str(log), "--from-step", "-3"],
        ["replay", str(log), "--to-step", "-1"],
        ["diff", str(log), str(log), "--from-step", "-2"],
        ["diff", str(log), str(log), "--to-step", "-2"],
        ["run", str(tmp_path / "s.yaml"), "--steps", "2.5"],
    ):
        got = subprocess.run([*isaac, *argv], cwd=ROOT, capture_output=True, text=True)
        assert got.returncode == 2, (argv, got.stderr)
        lines = got.stderr.strip().splitlines()
        option, value = argv[-2:]
        assert len(lines) == 1 and f"argument {option}:" in lines[0], (argv, got.stderr)
        assert f"got '{value}'" in lines[0], (argv, got.stderr)
    # a run of no steps is still one (its batches of 0 and max(0 - 1, 0) steps)
    none = subprocess.run([*isaac, "run", str(tmp_path / "s.yaml"), "--steps", "0"], cwd=ROOT)
    assert none.returncode == 0


# --- scenes built in Python -------------------------------------------------------------------


@pytest.fixture(scope="module")
def hostile_scene_outcomes() -> dict:
    """Every HOSTILE_SCENES case's outcome, from one child process (as `hostile_outcomes`)."""
    child = in_child(f"import api_hostile as h; h.run_scene_cases({list(HOSTILE_SCENES)!r})")
    outcomes = {"child": child}
    for line in child.stdout.splitlines():
        got = json.loads(line)
        outcomes[got["case"], got["staged"]] = got
    return outcomes


@pytest.mark.parametrize("staged", [False, True], ids=["driver", "staged"])
@pytest.mark.parametrize("name", list(HOSTILE_SCENES))
def test_a_scene_built_in_python_that_the_loader_would_refuse_is_refused_naming_its_field(
    hostile_scene_outcomes, name, staged
):
    child = hostile_scene_outcomes["child"]
    got = hostile_scene_outcomes.get((name, staged))
    assert got is not None, (
        f"the child died (exit status {child.returncode}) before reporting {name!r}:\n"
        + "\n".join(child.stderr.splitlines()[-15:])
    )
    assert got["raised"] == "SceneError", got
    assert HOSTILE_SCENES[name][1] in got["message"], got["message"]
    assert "\n" not in got["message"]


def test_a_scene_built_in_python_that_the_loader_would_take_runs_as_the_loaded_one():
    from isaac.scene import load_scene_text, scene_to_yaml

    mine = built()
    loaded = load_scene_text(scene_to_yaml(mine))
    a, b = Simulation(mine), Simulation(loaded)
    for _ in range(5):
        ra, rb = a.step(), b.step()
    assert state_hash(ra) == state_hash(rb)


def test_what_is_not_a_scene_is_a_type_error():
    with pytest.raises(TypeError, match="runs an isaac.scene.Scene, got str"):
        Simulation("scenes/bounce.yaml")


def test_every_shipped_scene_passes_the_python_check_as_it_loads():
    from isaac.scene.validate import check_scene

    for path in sorted((ROOT / "scenes").glob("*.yaml")):
        if not path.name.endswith(".sweep.yaml"):
            check_scene(load_scene(path))  # the full check, not the loader's remembered pass
