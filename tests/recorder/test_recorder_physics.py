"""Logs of real runs hold what the collisions should produce (checked from the log alone).

Scenes use ``fidelity: seed`` (one point per pair, one pass of the seed's impulse formula, full
MTD push) and no gravity, so every logged number can be recomputed exactly:

    j = -(1 + e) v_ab . n / (1/m_a + 1/m_b + (r_a x n)^2 / I_a + (r_b x n)^2 / I_b)

with v_ab the velocity of b's point minus a's point (the velocities logged on the step before),
r_a = point - (position of a logged on the step before + push_a), n the logged normal; 1/m and
1/I are 0 for a concrete body. Logs are decoded with google.protobuf from the descriptor set stored
in the file, not with the recorder's reader.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("isaac.engine.simulation")
from isaac.engine.simulation import Simulation  # noqa: E402
from isaac.scene import load_scene_text  # noqa: E402
from recorder import Recorder  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from test_recorder_mcap import generic_messages  # noqa: E402

HEAD_ON = """
name: head_on_log
world: {gravity: [0.0, 0.0], dt: 0.01, steps: 150, fidelity: seed}
bodies:
  - {name: left, shape: {box: [1.0, 1.0]}, position: [-2.0, 0.0], velocity: [3.0, 0.0],
     restitution: 1.0}
  - {name: right, shape: {box: [1.0, 1.0]}, position: [2.0, 0.0], restitution: 1.0}
"""

OFF_CENTRE = """
name: off_centre_log
world: {gravity: [0.0, 0.0], dt: 0.005, steps: 300, fidelity: seed}
bodies:
  - {name: striker, shape: {box: [1.0, 0.5]}, position: [-2.0, 0.4], velocity: [4.0, 0.0],
     angular_velocity: 0.3, restitution: 0.5, density: 2.0}
  - {name: target, shape: {box: [1.0, 1.0]}, position: [0.0, 0.0], angle: 0.2,
     restitution: 0.5}
"""

ONTO_CONCRETE = """
name: onto_concrete_log
world: {gravity: [0.0, 0.0], dt: 0.01, steps: 120, fidelity: seed}
bodies:
  - {name: floor, shape: {box: [10.0, 1.0]}, position: [0.0, -0.5], concrete: true}
  - {name: tile, shape: {regular: {sides: 5, radius: 0.4}}, position: [0.3, 1.5], angle: 0.1,
     velocity: [0.5, -3.0], angular_velocity: 1.0, restitution: 0.7}
"""

SCENES = {"head_on": HEAD_ON, "off_centre": OFF_CENTRE, "onto_concrete": ONTO_CONCRETE}


def _cross(r, n):
    return r[0] * n[1] - r[1] * n[0]


def _world_vertices(local, position, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.stack(
        [
            position[0] + c * local[:, 0] - s * local[:, 1],
            position[1] + s * local[:, 0] + c * local[:, 1],
        ],
        axis=1,
    )


def _overlap(pa, pb):
    """Penetration depth of two convex polygons by the separating axis test (<= 0: apart)."""
    best = np.inf
    for poly in (pa, pb):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        for n in normals:
            a, b = pa @ n, pb @ n
            best = min(best, min(a.max() - b.min(), b.max() - a.min()))
    return best


def logged_run(tmp_path, text):
    scene = load_scene_text(text, "<test>")
    sim = Simulation(scene)
    path = tmp_path / f"{scene.name}.mcap"
    with Recorder(sim, mcap_path=str(path)) as rec:
        rec.write(sim.record())
        for _ in range(scene.world.steps):
            rec.write(sim.step())
    msgs = generic_messages(path)
    world = [m for t, _, m in msgs if t == "/world"][0]
    bodies = {m.step: m for t, _, m in msgs if t == "/bodies"}
    contacts = {m.step: m for t, _, m in msgs if t == "/contacts"}
    return world, bodies, contacts


def _state(m):
    return (
        np.array(m.position).reshape(-1, 2),
        np.array(m.angle),
        np.array(m.velocity).reshape(-1, 2),
        np.array(m.angular_velocity),
    )


@pytest.mark.parametrize("name", sorted(SCENES))
def test_logged_collisions_match_the_seed_formulas(tmp_path, name):
    world, bodies, contacts = logged_run(tmp_path, SCENES[name])
    mass = np.array([b.mass for b in world.bodies])
    inertia = np.array([b.inertia for b in world.bodies])
    concrete = np.array([b.concrete for b in world.bodies])
    inv_m = np.where(concrete, 0.0, 1.0 / mass)
    inv_i = np.where(concrete, 0.0, 1.0 / inertia)
    local = [np.array(b.vertices_local).reshape(-1, 2) for b in world.bodies]
    hits = 0
    for step in sorted(contacts):
        c = contacts[step]
        if not len(c.a):
            continue
        hits += 1
        assert len(c.a) == 1  # one pair, one point (seed fidelity)
        a, b = c.a[0], c.b[0]
        assert a < b
        n = np.array(c.normal)
        point = np.array(c.point)
        push_a, push_b = np.array(c.push_a), np.array(c.push_b)
        assert np.linalg.norm(n) == pytest.approx(1.0, abs=1e-12)
        p0, ang0, v0, w0 = _state(bodies[step - 1])
        p1, ang1, v1, w1 = _state(bodies[step])

        # depth: the overlap of the polygons at the poses logged on the step before
        va = _world_vertices(local[a], p0[a], ang0[a])
        vb = _world_vertices(local[b], p0[b], ang0[b])
        # (one point: the pair's MTD and the point's own depth are the same number)
        assert c.pair_depth[0] == pytest.approx(_overlap(va, vb), abs=1e-9)
        assert c.point_depth[0] == c.pair_depth[0]
        # the push separates them (the seed's full MTD push: touching, no overlap left)
        pa_hit, pb_hit = p0[a] + push_a, p0[b] + push_b
        after = _overlap(
            _world_vertices(local[a], pa_hit, ang0[a]), _world_vertices(local[b], pb_hit, ang0[b])
        )
        assert after <= 1e-9

        # the impulse: the seed's formula from logged quantities
        r_a, r_b = point - pa_hit, point - pb_hit
        vel_a = v0[a] + w0[a] * np.array([-r_a[1], r_a[0]])
        vel_b = v0[b] + w0[b] * np.array([-r_b[1], r_b[0]])
        v_ab = vel_b - vel_a
        e = c.restitution[0]
        k = inv_m[a] + inv_m[b] + _cross(r_a, n) ** 2 * inv_i[a] + _cross(r_b, n) ** 2 * inv_i[b]
        j = -(1.0 + e) * float(v_ab @ n) / k
        assert c.impulse[0] == pytest.approx(j, rel=1e-9, abs=1e-12)
        assert c.impulse[0] > 0.0

        # velocity changes: +-j n / m and (r x j n) / I (gravity is off)
        jn = c.impulse[0] * n
        np.testing.assert_allclose(v1[a], v0[a] - jn * inv_m[a], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(v1[b], v0[b] + jn * inv_m[b], rtol=1e-9, atol=1e-12)
        assert w1[a] == pytest.approx(w0[a] - _cross(r_a, jn) * inv_i[a], rel=1e-9, abs=1e-12)
        assert w1[b] == pytest.approx(w0[b] + _cross(r_b, jn) * inv_i[b], rel=1e-9, abs=1e-12)
    assert hits >= 1


def test_head_on_equal_masses_exchange_velocities_in_the_log(tmp_path):
    _, bodies, _ = logged_run(tmp_path, HEAD_ON)
    _, _, v, _ = _state(bodies[max(bodies)])
    np.testing.assert_allclose(v, [[0.0, 0.0], [3.0, 0.0]], atol=1e-12)


def test_log_alone_is_enough_to_resimulate_bit_for_bit(tmp_path):
    from isaac.engine import diagnostics
    from recorder.reader import LogReader

    _world, _bodies, _contacts = logged_run(tmp_path, OFF_CENTRE)
    log = LogReader(str(tmp_path / "off_centre_log.mcap"))
    sim = Simulation(log.scene())
    logged = list(log.steps())
    assert diagnostics.state_hash(sim.record()) == logged[0].stats["state_hash"]
    for s in logged[1:]:
        r = sim.step()
        assert diagnostics.state_hash(r) == s.stats["state_hash"], s.step
        np.testing.assert_array_equal(r.contacts.impulse, s.record.contacts.impulse)


def test_two_runs_of_a_scene_give_identical_payloads_and_files(tmp_path):
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    logged_run(tmp_path / "one", ONTO_CONCRETE)
    logged_run(tmp_path / "two", ONTO_CONCRETE)
    one = (tmp_path / "one" / "onto_concrete_log.mcap").read_bytes()
    two = (tmp_path / "two" / "onto_concrete_log.mcap").read_bytes()
    assert one == two
