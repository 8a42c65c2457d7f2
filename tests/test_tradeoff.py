"""`isaac tradeoff`: the grid, the analytic references, the comparison and the command."""

from __future__ import annotations

import csv
import math
from dataclasses import replace

import numpy as np
import pytest
from physics_helpers import LEDGE, ROTOR, box, scene

from isaac.app.cli import main
from isaac.app.tradeoff import (
    GridPoint,
    TradeoffError,
    analytic_model,
    analytic_trajectory,
    measure,
    parse_grid,
    sample_times,
    simulate,
)
from isaac.app.tradeoff.measure import _pareto
from isaac.app.tradeoff.report import format_table
from isaac.engine.simulation import Simulation
from isaac.scene import PRESETS, BodySpec, Scene, load_scene
from isaac.scene.spec import JointSpec

G = 9.81


# --- grid -----------------------------------------------------------------------------------


def test_default_grid_is_the_presets_times_three_dt_values():
    grid = parse_grid(None, 0.01)
    assert [(p.label, p.dt) for p in grid] == [
        (preset, dt)
        for preset in ("seed", "fast", "balanced", "accurate")
        for dt in (0.02, 0.01, 0.005)
    ]


def test_grid_axes_multiply_and_read_like_a_scene():
    grid = parse_grid(["preset=fast,balanced", "iterations=4,20;dt=1/60,x2"], 0.01)
    assert len(grid) == 2 * 2 * 2
    assert grid[0].overrides == (("preset", "fast"), ("iterations", 4))
    assert [p.dt for p in grid[:2]] == [1 / 60, 0.02]
    assert grid[0].label == "fast iterations=4"


@pytest.mark.parametrize(
    "spec, message",
    [
        ("preset=quick", "unknown preset 'quick'"),
        ("substeps=0", "out of range"),
        ("ccd=maybe", "ccd"),
        ("dt=0", "out of range"),
        ("dt=abc", "cannot read 'abc'"),
        ("colour=red", "unknown axis 'colour'"),
        ("iterations", "expected KEY=V1,V2"),
    ],
)
def test_bad_grid_is_refused_with_a_clear_message(spec, message):
    with pytest.raises(TradeoffError, match=message):
        parse_grid([spec], 0.01)


def test_grid_point_applies_the_preset_and_keeps_the_scene_physics():
    base = load_scene("scenes/pile.yaml").world
    world = GridPoint("fast", 0.005, (("preset", "fast"),)).world(base, duration=2.0)
    for key, value in PRESETS["fast"].items():
        assert getattr(world, key) == value
    assert world.friction is True and world.gravity == base.gravity  # the scene's, not preset's
    assert world.dt == 0.005 and world.steps == 400


# --- analytic references ----------------------------------------------------------------------


def test_shipped_scenes_are_classified():
    assert analytic_model(load_scene("scenes/bounce.yaml")) == "drop"
    assert analytic_model(load_scene("scenes/head_on.yaml")) == "head_on"
    assert analytic_model(load_scene("scenes/off_centre.yaml")) is None  # off-centre: spins
    assert analytic_model(load_scene("scenes/pyramid.yaml")) is None


def test_analytic_drop_lands_and_bounces_at_the_closed_form_times():
    sc = load_scene("scenes/bounce.yaml")  # bottom at 4.5 m, e = 0.8, threshold 1 m/s
    t_land = math.sqrt(2 * 4.5 / G)
    v_land = G * t_land
    times = np.array([0.0, t_land, t_land + 0.8 * v_land / G])
    traj = analytic_trajectory(sc, times)
    y, v = traj.position[:, 1, 1], traj.velocity[:, 1, 1]
    assert y[0] == 5.0 and y[1] == pytest.approx(0.5, abs=1e-12)
    # the top of the first bounce: rises (0.8 v)^2 / 2g, velocity zero
    assert y[2] == pytest.approx(0.5 + (0.8 * v_land) ** 2 / (2 * G), rel=1e-12)
    assert v[2] == pytest.approx(0.0, abs=1e-12)


def test_analytic_drop_comes_to_rest_below_the_restitution_threshold():
    sc = load_scene("scenes/bounce.yaml")
    traj = analytic_trajectory(sc, np.array([20.0]))
    assert traj.position[0, 1, 1] == pytest.approx(0.5) and traj.velocity[0, 1, 1] == 0.0


def test_analytic_head_on_exchanges_velocities_and_keeps_momentum():
    sc = load_scene("scenes/head_on.yaml")  # equal boxes, e = 1, 3 m/s, contact at t = 1 s
    traj = analytic_trajectory(sc, np.array([0.5, 1.5]))
    assert traj.velocity[0, :, 0].tolist() == [3.0, 0.0]
    assert traj.velocity[1, :, 0].tolist() == [0.0, 3.0]
    assert traj.position[1, 1, 0] == pytest.approx(2.0 + 3.0 * 0.5, abs=1e-12)  # hit at 1 s
    assert traj.position[1, 0, 0] == pytest.approx(-2.0 + 3.0 * 1.0, abs=1e-12)  # stopped


def test_analytic_ballistic_is_the_parabola():
    sc = scene(box("ball", velocity=(1.0, 2.0), angular_velocity=0.5), gravity=(0.0, -G))
    assert analytic_model(sc) == "ballistic"
    traj = analytic_trajectory(sc, np.array([2.0]))
    assert traj.position[0, 0].tolist() == pytest.approx([2.0, 4.0 - 0.5 * G * 4.0])
    assert traj.angle[0, 0] == pytest.approx(1.0)


def test_declared_model_that_does_not_fit_is_refused():
    sc = replace(load_scene("scenes/pyramid.yaml"), analytic={"model": "drop"})
    with pytest.raises(TradeoffError, match="declares analytic model 'drop'"):
        analytic_model(sc)


# --- runs and comparisons ---------------------------------------------------------------------


def test_samples_are_the_states_at_common_times():
    sc = load_scene("scenes/bounce.yaml")
    sc = replace(sc, world=replace(sc.world, steps=60))
    times = sample_times(0.5, 1 / 60)  # every second step of 1/120 s
    traj = simulate(sc, times)
    sim = Simulation(sc)
    records = [sim.record()] + list(sim.run(60))
    for k, t in enumerate(times):
        assert np.array_equal(traj.position[k], records[round(t * 120)].position)


def test_samples_between_steps_are_interpolated():
    sc = scene(box("ball", velocity=(1.0, 0.0)), gravity=(0.0, 0.0), dt=0.01, steps=10)
    traj = simulate(sc, np.array([0.0, 0.015, 0.1]))
    assert traj.position[:, 0, 0] == pytest.approx([0.0, 0.015, 0.1], abs=1e-15)


def _assert_the_shot_tunnels_only_without_ccd(target) -> None:
    """A 0.1 m box at 200 m/s through a thin concrete `target` in one 1/60 s step: counted as
    tunneled with ccd off, stopped (not counted) with speculative contacts."""

    def shot(ccd):
        return scene(
            target,
            box("bullet", 0.1, 0.1, position=(-0.5, 0.0), velocity=(200.0, 0.0)),
            preset="balanced",
            ccd=ccd,
            gravity=(0.0, 0.0),
            dt=1 / 60,
            steps=10,
        )

    times = sample_times(10 / 60, 1 / 60)
    assert simulate(shot("off"), times).tunneled == ["bullet"]
    assert simulate(shot("speculative"), times).tunneled == []


def test_tunneling_through_concrete_is_detected():
    _assert_the_shot_tunnels_only_without_ccd(box("wall", 0.05, 4.0, concrete=True))


def test_resting_body_is_not_counted_as_tunneling():
    sc = load_scene("scenes/bounce.yaml")
    assert simulate(sc, sample_times(5.0, 0.1)).tunneled == []


def test_pareto_front_keeps_only_undominated_points():
    pts = [(1.0, 5.0), (2.0, 2.0), (3.0, 3.0), (4.0, 1.0), (math.nan, 0.1)]
    assert _pareto(pts) == [True, True, False, True, False]


def test_measure_bounce_error_shrinks_with_dt_and_reference_row_is_exact():
    sc = load_scene("scenes/bounce.yaml")
    grid = parse_grid(["preset=balanced", "dt=1/60,1/120,1/240"], sc.world.dt)
    result = measure(sc, grid, reference="analytic", duration=2.0, repeats=1, min_seconds=0.0)
    assert result.reference == "analytic (drop)"
    assert result.reference_row["rms_error_m"] == 0.0
    errors = [r["rms_error_m"] for r in result.rows]
    assert errors[0] > errors[1] > errors[2] > 0.0
    for row in result.rows:
        assert row["ms_per_step"] > 0.0 and row["steps_per_s"] == pytest.approx(
            1e3 / row["ms_per_step"]
        )
        assert row["ms_per_sim_s"] == pytest.approx(row["ms_per_step"] / row["dt"])
        assert row["tunneled"] == 0 and row["diverged"] == ""


def test_measure_against_accurate_reference_on_a_tiny_scene():
    sc = scene(
        box("ground", 10.0, 1.0, position=(0.0, -0.5), concrete=True),
        box("box", position=(0.0, 1.0), restitution=0.5),
        preset="balanced",
        gravity=(0.0, -G),
        dt=1 / 60,
        steps=60,
    )
    grid = parse_grid(["preset=seed,accurate", "dt=1/60"], sc.world.dt)
    result = measure(sc, grid, repeats=1, min_seconds=0.0)
    assert result.reference.startswith("accurate, dt=")
    assert result.reference_row["dt"] == pytest.approx(1 / 480)
    seed, accurate = result.rows
    assert accurate["rms_error_m"] < seed["rms_error_m"]
    assert accurate["max_penetration_m"] < seed["max_penetration_m"]


# --- the command ------------------------------------------------------------------------------


def test_command_writes_table_csv_and_plot(tmp_path, capsys):
    csv_path, png_path = tmp_path / "out.csv", tmp_path / "out.png"
    status = main(
        [
            "tradeoff",
            "scenes/bounce.yaml",
            "--grid",
            "preset=fast,balanced",
            "--grid",
            "dt=1/60,1/120",
            "--duration",
            "1",
            "--repeats",
            "1",
            "--min-time",
            "0",
            "--quiet",
            "--csv",
            str(csv_path),
            "--png",
            str(png_path),
        ]
    )
    assert status == 0
    out = capsys.readouterr().out
    assert "reference: analytic (drop)" in out and "ms/step" in out and "RMS err m" in out
    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    assert [r["setting"] for r in rows] == ["analytic", "fast", "fast", "balanced", "balanced"]
    assert all(float(r["rms_error_m"]) >= 0.0 for r in rows)
    assert png_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png_path.stat().st_size < 200_000


def test_command_turns_a_bad_grid_into_one_line(capsys):
    status = main(["tradeoff", "scenes/bounce.yaml", "--grid", "preset=quick", "--quiet"])
    assert status == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown preset 'quick'" in err[0]


def test_command_refuses_analytic_reference_for_a_pile(capsys):
    status = main(
        [
            "tradeoff",
            "scenes/pyramid.yaml",
            "--reference",
            "analytic",
            "--quiet",
            "--duration",
            "0.1",
        ]
    )
    assert status == 2
    assert "no closed form known" in capsys.readouterr().err


# --- circles and joints -----------------------------------------------------------------------


def _disc(name, radius=0.5, **fields) -> BodySpec:
    return BodySpec(name=name, vertices=(), circle=radius, **fields)


def _disc_drop(**world) -> Scene:
    """A disc of radius 0.5 m dropped from 5 m onto level concrete ground (top at y = 0)."""
    return scene(
        box("ground", 10.0, 1.0, position=(0.0, -0.5), concrete=True, restitution=0.8),
        _disc("disc", position=(0.0, 5.0), restitution=0.8),
        gravity=(0.0, -G),
        **{"preset": "balanced", "dt": 1 / 60, "steps": 120, **world},
    )


def test_a_dropped_disc_is_the_drop_closed_form_and_lands_on_its_rim():
    sc = _disc_drop()
    assert analytic_model(sc) == "drop"
    t_land = math.sqrt(2 * 4.5 / G)  # its lowest point falls 4.5 m
    traj = analytic_trajectory(sc, np.array([0.0, 0.5 * t_land, t_land]))
    assert traj.position[:, 1, 1] == pytest.approx(
        [5.0, 5.0 - 0.5 * G * (0.5 * t_land) ** 2, 0.5], abs=1e-12
    )
    assert traj.velocity[1, 1, 1] == pytest.approx(-G * 0.5 * t_land, rel=1e-12)
    assert traj.velocity[2, 1, 1] == pytest.approx(0.8 * G * t_land, rel=1e-12)  # bounced


def test_the_engines_disc_drop_approaches_the_closed_form_as_dt_shrinks():
    sc = _disc_drop()
    grid = parse_grid(["preset=balanced", "dt=1/60,1/120,1/240"], sc.world.dt)
    result = measure(sc, grid, reference="analytic", duration=2.0, repeats=1, min_seconds=0.0)
    assert result.reference == "analytic (drop)"
    errors = [r["rms_error_m"] for r in result.rows]
    assert errors[0] > errors[1] > errors[2] > 0.0
    assert errors[2] < 0.02  # m, over two bounces
    assert all(r["tunneled"] == 0 and r["max_joint_error_m"] == 0.0 for r in result.rows)


def test_two_discs_head_on_are_the_head_on_closed_form_unless_joined():
    a = _disc("a", position=(-2.0, 0.0), velocity=(3.0, 0.0), restitution=1.0)
    b = _disc("b", position=(2.0, 0.0), restitution=1.0)
    sc = scene(a, b, gravity=(0.0, 0.0), dt=0.01, steps=200)
    assert analytic_model(sc) == "head_on"
    traj = analytic_trajectory(sc, np.array([0.5, 1.5]))  # rims meet at t = 3 m / 3 m/s = 1 s
    assert traj.velocity[:, :, 0].tolist() == [[3.0, 0.0], [0.0, 3.0]]
    rod = JointSpec(
        name="rod", kind="distance", a=0, b=1, local_a=(0.0, 0.0), local_b=(0.0, 0.0), length=4.0
    )
    joined = replace(sc, joints=(rod,))
    assert analytic_model(joined) is None  # held by the rod: no free flight
    with pytest.raises(TradeoffError, match="it has joints"):
        analytic_model(replace(joined, analytic={"model": "head_on"}))


def test_analytic_reference_refuses_the_pendulum_in_one_line(capsys):
    status = main(
        ["tradeoff", "scenes/pendulum.yaml", "--reference", "analytic", "--quiet",
         "--duration", "0.1"]
    )  # fmt: skip
    assert status == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no closed form known" in err[0]


def test_a_shot_through_a_concrete_disc_is_counted_as_tunneling():
    _assert_the_shot_tunnels_only_without_ccd(_disc("post", 0.05, concrete=True))


def test_measure_on_the_chain_reports_each_runs_largest_joint_error():
    sc = load_scene("scenes/chain.yaml")
    grid = parse_grid(["preset=fast,balanced", "dt=x1"], sc.world.dt)
    result = measure(sc, grid, duration=0.5, repeats=1, min_seconds=0.0)
    assert result.joints
    for point, row in zip(grid, result.rows):
        # recomputed from a run of that setting's own records (by the compiled driver; the
        # measurement steps one at a time)
        run_scene = replace(sc, world=point.world(sc.world, 0.5))
        errors = [float(r.joints.error[:, 0].max()) for r in Simulation(run_scene).run()]
        assert row["max_joint_error_m"] == max(errors) > 0.0
        assert row["diverged"] == "" and row["rms_error_m"] < 0.05
    assert "joint err m" in format_table(result)
    assert "joint err m" not in format_table(
        measure(_disc_drop(), grid[:1], duration=0.2, repeats=1, min_seconds=0.0)
    )


@pytest.mark.parametrize("name", ["rolling", "chain"])
def test_the_command_runs_on_a_shipped_scene_with_circles_or_joints(tmp_path, capsys, name):
    csv_path = tmp_path / "out.csv"
    status = main(
        ["tradeoff", f"scenes/{name}.yaml", "--grid", "preset=fast,balanced;dt=x1", "--duration",
         "0.5", "--repeats", "1", "--min-time", "0", "--quiet", "--csv", str(csv_path),
         "--no-plot"]
    )  # fmt: skip
    assert status == 0
    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    assert [r["setting"] for r in rows] == ["accurate (reference)", "fast", "balanced"]
    for r in rows:
        assert math.isfinite(float(r["rms_error_m"])) and r["diverged"] == ""
        assert float(r["max_joint_error_m"]) < 1e-2
    assert ("joint err m" in capsys.readouterr().out) == (name == "chain")


def test_the_default_grid_of_a_scene_with_joints_leaves_out_the_seed_preset():
    grid = parse_grid(None, 0.01, joints=True)
    assert sorted({p.label for p in grid}) == ["accurate", "balanced", "fast"]
    assert len(grid) == 3 * 3


def test_the_seed_solver_on_a_scene_with_joints_is_refused_in_one_line(capsys):
    status = main(
        ["tradeoff", "scenes/pendulum.yaml", "--grid", "preset=seed,balanced", "--quiet",
         "--duration", "0.1"]
    )  # fmt: skip
    assert status == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--grid seed" in err[0] and "sequential solver" in err[0]


@pytest.mark.parametrize("prefilter", [True, False], ids=["bounding boxes first", "every path"])
def test_a_sweep_counts_a_shot_through_a_concrete_disc_beside_a_wall(prefilter, monkeypatch):
    # the sweep's metric shares the tradeoff's clipping: a concrete disc and a concrete wall,
    # one bullet through both, one over the wall and past the disc
    from isaac.app.sweep import metrics

    sc = scene(
        _disc("post", 0.05, concrete=True),
        box("wall", 0.05, 4.0, position=(5.0, 0.0), concrete=True),
        box("through", 0.1, 0.1, position=(-0.5, 0.0), velocity=(200.0, 0.0)),
        box("over", 0.1, 0.1, position=(-0.5, 3.0), velocity=(200.0, 0.0)),
        preset="balanced",
        ccd="off",
        gravity=(0.0, 0.0),
        dt=1 / 60,
        steps=10,
    )
    monkeypatch.setattr(metrics, "PREFILTER_PATHS", 0 if prefilter else 10**9)
    sim = Simulation(sc)
    m = metrics.Measure(sim, ["tunneled"], [])
    for batch in sim.batches(10, size=4):
        m.add(batch)
    assert m.values()["tunneled_bodies"] == "through"
    assert simulate(sc, sample_times(10 / 60, 1 / 60)).tunneled == ["through"]


@pytest.mark.parametrize(
    "name, second", [("pendulum", "max_joint_error_m"), ("bounce", "max_penetration_m")]
)
def test_the_plots_second_panel_shows_the_joint_error_for_a_scene_with_joints(
    tmp_path, monkeypatch, name, second
):
    from isaac.app.tradeoff import command

    shown = []
    monkeypatch.setattr(command, "plot", lambda result, path, second: shown.append(second))
    status = main(
        ["tradeoff", f"scenes/{name}.yaml", "--grid", "preset=fast;dt=x1", "--duration", "0.2",
         "--repeats", "1", "--min-time", "0", "--quiet", "--csv", str(tmp_path / "o.csv"),
         "--png", str(tmp_path / "o.png")]
    )  # fmt: skip
    assert status == 0 and shown == [second]


def _checked(text: str):
    """The tradeoff's trajectory of the scene `text`, after checking that the sweep's
    `tunneled` metric names the same bodies (both apply one rule)."""
    from isaac.app.sweep import metrics
    from isaac.scene import load_scene_text

    sc = load_scene_text(text)
    traj = simulate(sc, sample_times(sc.world.steps * sc.world.dt, sc.world.dt))
    sim = Simulation(sc)
    m = metrics.Measure(sim, ["tunneled"], [])
    for batch in sim.batches(sc.world.steps, size=4):
        m.add(batch)
    assert m.values()["tunneled_bodies"] == ",".join(traj.tunneled)
    return traj


def test_a_blade_on_an_axle_through_a_concrete_hub_has_not_tunneled():
    traj = _checked(ROTOR)
    # the blade's centre stays inside the hub: without the joint's rule it would count
    assert np.abs(traj.position[:, 1] - [0.0, 2.0]).max() < 0.15
    assert traj.tunneled == []


def test_a_box_its_mask_keeps_from_a_concrete_ledge_falls_through_untunneled():
    traj = _checked(LEDGE)
    assert traj.position[-1, 1, 1] < -0.5  # it fell through the ledge (top at y = 0.1)
    assert traj.tunneled == []
    # the same fall where its mask lets the pair collide and nothing stops it (ccd off, a
    # thin ledge, 1 m per step): a tunnel
    thin = LEDGE.replace(", mask: 0x1", ", velocity: [0.0, -100.0]")
    thin = thin.replace("[4.0, 0.2]", "[4.0, 0.02]").replace("steps: 60", "steps: 5")
    thin = thin.replace("world: {", 'world: {ccd: "off", ')
    assert _checked(thin).tunneled == ["ghost"]


def test_a_bullet_through_the_tunnel_scenes_wall_still_tunnels():
    sc = load_scene("scenes/tunnel.yaml")
    off = replace(sc, world=replace(sc.world, ccd="off"))
    assert simulate(off, sample_times(1.0, sc.world.dt)).tunneled == ["bullet"]
    # the wall entering after the bullet crossed its place: nothing was there to stop it
    late = replace(off, bodies=[replace(sc.bodies[0], enters_at=0.5), sc.bodies[1]])
    assert simulate(late, sample_times(1.0, sc.world.dt)).tunneled == []
