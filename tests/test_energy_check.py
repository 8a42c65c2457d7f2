"""The energy check (isaac.engine.energy_check): a run whose energy rises beyond its sources is
said to, in `isaac run`'s summary and a warning, `isaac inspect` and the sweep's rows, and
`isaac check` warns ahead of time of the joint geometry that does it.

Claims: the threshold logic on synthetic energy series (a rise is flagged at its step, energy
brought by bodies entering is not, the datum does not matter, a motor scene is not checked);
the scale is its closed form; the issue's two repros (a pinned chain of 20 0.1 x 0.02 m links,
a distance joint anchored 1 m off a 0.1 m box, dt 1/120 s under `balanced`) are flagged while
the shipped scenes are not; `isaac check` warns of both repros' geometry and of no shipped
joint scene.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from isaac.app.cli import main
from isaac.engine.energy_check import ENERGY_TOLERANCE, EnergyCheck, energy_scale
from isaac.scene import load_scene, load_scene_text
from isaac.scene.warnings import scene_warnings

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"


def chain_yaml(n: int, *, steps: int = 300, substeps: int = 1) -> str:
    """The issue's repro: n links of 0.1 x 0.02 m on revolute joints, the first pinned to a
    concrete pivot, released horizontal; collisions filtered off (one negative group)."""
    lines = [
        f"name: chain{n}",
        "world: {gravity: [0.0, -9.81], dt: 1/120, " + f"steps: {steps}, substeps: {substeps}}}",
        "bodies:",
        "  - {name: pivot, shape: {box: [0.1, 0.1]}, position: [0.0, 0.0], concrete: true, "
        "group: -1}",
    ]
    lines += [
        f"  - {{name: link{i}, shape: {{box: [0.1, 0.02]}}, position: [{0.05 + 0.1 * i:.4f}, "
        "0.0], group: -1}"
        for i in range(n)
    ]
    lines += ["joints:", "  - {name: pin, type: revolute, bodies: [pivot, link0], anchor: [0, 0]}"]
    lines += [
        f"  - {{name: j{i}, type: revolute, bodies: [link{i - 1}, link{i}], anchor: "
        f"[{0.1 * i:.4f}, 0.0]}}"
        for i in range(1, n)
    ]
    return "\n".join(lines) + "\n"


DISTANCE_YAML = """\
name: distance_far
world: {gravity: [0.0, -9.81], dt: 1/120, steps: 120}
bodies:
  - {name: pivot, shape: {box: [0.1, 0.1]}, position: [0.0, 0.0], concrete: true}
  - {name: bob, shape: {box: [0.1, 0.1]}, position: [1.0, -1.0]}
joints:
  - {name: rod, type: distance, bodies: [pivot, bob], anchor_a: [0, 0], anchor_b: [0.0, -1.0]}
"""


# -- the threshold logic, on synthetic series ------------------------------------------------


def _check(total, entered=None, *, start=10.0, scale=4.0, motors=False, batches=1):
    c = EnergyCheck(0, start, scale, motors=motors)
    total = np.asarray(total, dtype=float)
    entered = np.zeros_like(total) if entered is None else np.asarray(entered, dtype=float)
    for t, e in zip(np.array_split(total, batches), np.array_split(entered, batches)):
        c.add(t, e)
    return c


def test_energy_that_only_falls_or_wobbles_within_the_tolerance_is_not_flagged():
    wobble = 10.0 + 0.99 * ENERGY_TOLERANCE * 4.0 * np.sin(np.arange(200))
    c = _check(np.minimum(wobble, 10.0 + 0.99 * ENERGY_TOLERANCE * 4.0))
    assert not c.flagged and c.step is None and c.warning() is None
    assert c.threshold == ENERGY_TOLERANCE * 4.0
    assert not _check(np.linspace(10.0, -50.0, 100)).flagged


@pytest.mark.parametrize("batches", [1, 3, 7])
def test_a_rise_past_the_threshold_is_flagged_at_its_first_step_whatever_the_batches(batches):
    total = np.full(50, 10.0)
    total[20:] = 10.0 + 1.01 * ENERGY_TOLERANCE * 4.0  # step 21 (the first fed is step 1)
    total[40] = 1e9
    c = _check(total, batches=batches)
    assert c.flagged and c.step == 21
    assert c.rise == pytest.approx(1.01 * ENERGY_TOLERANCE * 4.0)
    assert c.max_excess == pytest.approx(1e9 - 10.0) and c.max_excess_step == 41
    assert "step 21" in c.warning() and "sub-steps" in c.warning()


def test_energy_brought_by_bodies_entering_is_a_source_and_leaving_takes_it_out():
    total = np.full(30, 10.0)
    entered = np.zeros(30)
    total[10:] += 100.0  # a body bringing 100 J enters at step 11
    entered[10] = 100.0
    assert not _check(total, entered, batches=4).flagged
    # it leaves at step 21: its energy leaves the budget; a rise after that is flagged
    total[20:] -= 100.0
    entered[20] = -100.0
    assert not _check(total, entered).flagged
    total[25:] += 100.0
    assert _check(total, entered).step == 26


def test_the_check_does_not_depend_on_where_y_is_zero():
    rng = np.random.default_rng(3)
    total = 10.0 + np.cumsum(rng.normal(0.0, 0.3, 100))
    entered = np.where(rng.random(100) < 0.1, 5.0, 0.0)
    a = _check(total + np.cumsum(entered), entered)
    # the datum moved: every energy (start, series, the entering bodies') shifted by M g h
    shift = 1234.5
    b = _check(total + np.cumsum(entered) + shift, entered, start=10.0 + shift)
    assert (a.step, a.max_excess_step) == (b.step, b.max_excess_step)
    assert a.max_excess == pytest.approx(b.max_excess, abs=1e-9)


def test_a_scene_with_a_motor_is_not_checked():
    c = _check(np.full(10, 1e9), motors=True)
    assert not c.checked and not c.flagged and "motor" in c.summary()


def test_the_scale_is_kinetic_energy_plus_g_times_mass_times_the_scene_size():
    # two movable boxes and a concrete one: centres spread 3 m in x, 1 m in y, radius 0.5
    mass = np.array([2.0, 3.0, 7.0])
    concrete = np.array([False, False, True])
    position = np.array([[0.0, 0.0], [3.0, 1.0], [1.0, 0.5]])
    velocity = np.array([[1.0, 0.0], [0.0, 2.0], [0.0, 0.0]])
    omega = np.array([0.0, 1.0, 0.0])
    inertia = np.array([0.5, 0.25, 1.0])
    radius = np.full(3, 0.5)
    kinetic = 0.5 * 2.0 * 1.0 + 0.5 * 3.0 * 4.0 + 0.5 * 0.25 * 1.0
    s = energy_scale(mass, concrete, position, velocity, omega, inertia, radius, (0.0, -9.81))
    assert s == pytest.approx(kinetic + 9.81 * 5.0 * (3.0 + 1.0))


# -- the runs: the repros flagged, the shipped scenes not ------------------------------------


def _scene_file(tmp_path: Path, text: str, name: str) -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize("which", ["chain", "distance"])
def test_the_repros_are_flagged_in_the_run_summary_and_a_warning_with_exit_0(
    tmp_path, capsys, which
):
    text = chain_yaml(20) if which == "chain" else DISTANCE_YAML
    scene = _scene_file(tmp_path, text, f"{which}.yaml")
    assert main(["run", scene, "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "energy check: ROSE by" in out
    assert "isaac run: warning: energy rose by" in err and "sub-steps" in err


def test_a_shipped_scene_is_not_flagged_in_the_run_summary(capsys):
    assert main(["run", str(SCENES / "double_pendulum.yaml"), "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "energy check: ok" in out and "energy rose" not in err


def test_inspect_says_the_step_the_energy_rose_at(tmp_path, capsys):
    scene = _scene_file(tmp_path, chain_yaml(20), "chain.yaml")
    log = str(tmp_path / "chain.mcap")
    assert main(["run", scene, "--quiet", "--mcap", log]) == 0
    summary_line = next(
        line for line in capsys.readouterr().out.splitlines() if "energy check" in line
    )
    assert main(["inspect", log]) == 0
    out, err = capsys.readouterr()
    # the same check as the run's, from the log's /stats
    assert summary_line.strip() in out
    assert "at step" in summary_line and "isaac inspect: warning: energy rose by" in err


def test_inspect_of_a_scene_with_bodies_entering_is_not_flagged(tmp_path, capsys):
    log = str(tmp_path / "spawn.mcap")
    assert main(["run", str(SCENES / "spawn.yaml"), "--quiet", "--mcap", log]) == 0
    capsys.readouterr()
    assert main(["inspect", log]) == 0
    out, err = capsys.readouterr()
    assert "energy check: ok" in out and "energy rose" not in err


def _measured(scene):
    from isaac.app.sweep.metrics import Measure
    from isaac.engine.simulation import Simulation

    sim = Simulation(scene)
    m = Measure(sim, ("energy_drift",), ())
    for batch in sim.batches(scene.world.steps, size=64):
        m.add(batch)
    return m.values()


def test_the_sweep_row_flags_the_repro_and_not_a_shipped_scene():
    from isaac.app.sweep.metrics import columns

    names = [f.name for f in columns(("energy_drift",), ())]
    assert "energy_rose" in names and "energy_rose_step" in names
    row = _measured(load_scene_text(chain_yaml(20), "chain.yaml"))
    assert row["energy_rose"] is True and row["energy_rose_step"] > 0
    row = _measured(load_scene(SCENES / "pendulum.yaml"))
    assert row["energy_rose"] is False and row["energy_rose_step"] is None


SHIPPED = sorted(p.name for p in SCENES.glob("*.yaml") if not p.name.endswith(".sweep.yaml"))
LONG = {"pile.yaml", "pyramid.yaml", "chain.yaml", "newton_cradle.yaml", "mass_ratio.yaml"}


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=pytest.mark.slow) if n in LONG else n for n in SHIPPED]
)
def test_no_shipped_scene_is_flagged_over_its_whole_run(name):
    row = _measured(load_scene(SCENES / name))
    assert row["energy_rose"] is False


# -- isaac check: the joint geometry ---------------------------------------------------------


def test_check_warns_of_both_repros_geometry_naming_the_sub_steps():
    chain = scene_warnings(load_scene_text(chain_yaml(20), "chain.yaml"))
    assert any("a chain of 20 links" in w and "world.substeps: 2" in w for w in chain)
    far = scene_warnings(load_scene_text(DISTANCE_YAML, "far.yaml"))
    assert any("'rod'" in w and "1 m from its centre" in w and "substeps: 16" in w for w in far)


def test_the_sub_steps_the_warning_names_hold_the_chain():
    scene = load_scene_text(chain_yaml(20, substeps=2), "chain.yaml")
    assert not any("chain" in w for w in scene_warnings(scene))
    assert _measured(scene)["energy_rose"] is False


@pytest.mark.parametrize(
    "name", ["chain", "pendulum", "double_pendulum", "car", "newton_cradle", "filtering"]
)
def test_check_does_not_warn_of_the_shipped_joint_scenes(name):
    warnings = scene_warnings(load_scene(SCENES / f"{name}.yaml"))
    assert not any("energy from nowhere" in w for w in warnings)
