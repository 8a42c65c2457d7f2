"""Collision filtering: categories, masks and groups (Box2D's rule), dropped in the broad phase."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from isaac.collision_filter import colliders, collides
from isaac.engine.simulation import Simulation
from isaac.errors import SceneError
from isaac.scene import load_scene, load_scene_text, scene_to_yaml


def _pairs_touching(sim: Simulation, steps: int) -> set[tuple[str, str]]:
    names = sim.model.names
    seen = set()
    for rec in sim.run(steps):
        for a, b in zip(rec.contacts.a, rec.contacts.b):
            seen.add((names[a], names[b]))
    return seen


def _falling_pair(a_filter: str, b_filter: str) -> Simulation:
    """Box `top` dropped onto box `low`, which rests on concrete ground."""
    return Simulation(
        load_scene_text(
            f"""
world: {{steps: 120, dt: 1/120}}
bodies:
  - {{name: ground, shape: {{box: [10, 1]}}, position: [0, -0.5], concrete: true}}
  - {{name: low, shape: {{box: [1, 1]}}, position: [0, 0.5] {b_filter}}}
  - {{name: top, shape: {{box: [1, 1]}}, position: [0, 2.0] {a_filter}}}
""",
            "<test>",
        )
    )


@pytest.mark.parametrize(
    "top, low, meet",
    [
        ("", "", True),
        (", group: -1", ", group: -1", False),  # a shared negative group never collides
        (", group: -1", ", group: -2", True),  # different groups: the bits decide
        (", category: 2, mask: 0xFFFFFFFB", ", category: 4", False),  # top leaves out 4
        (", category: 2", ", mask: 0xFFFFFFFD", False),  # low leaves out top's category 2
        # a shared positive group collides whatever the bits say
        (", category: 2, mask: 0xFFFFFFFB, group: 3", ", category: 4, group: 3", True),
    ],
)
def test_filters_decide_which_pairs_collide_from_both_sides(top, low, meet):
    sim = _falling_pair(top, low)
    touching = _pairs_touching(sim, 120)
    assert (("low", "top") in touching) == meet
    assert ("ground", "low") in touching  # the ground's default filter takes everything
    top_y = sim.body("top").position[1]
    if meet:
        assert top_y == pytest.approx(1.5, abs=0.02)  # resting on low
    else:
        assert top_y == pytest.approx(0.5, abs=0.02)  # fell through low onto the ground


def test_the_rule_is_the_same_on_arrays_and_on_numbers():
    values = [(1, 0xFFFFFFFF, 0), (2, 1, 0), (4, 6, -1), (1, 0, -1), (8, 0, 5), (2, 4, 5)]
    pairs = list(itertools.product(values, repeat=2))
    a = np.array([p[0] for p in pairs], dtype=np.int64)
    b = np.array([p[1] for p in pairs], dtype=np.int64)
    on_arrays = collides(a[:, 0], a[:, 1], a[:, 2], b[:, 0], b[:, 1], b[:, 2])
    for k, ((ca, ma, ga), (cb, mb, gb)) in enumerate(pairs):
        if ga == gb and ga != 0:
            expected = ga > 0
        else:
            expected = (ma & cb) != 0 and (mb & ca) != 0
        assert bool(collides(ca, ma, ga, cb, mb, gb)) is expected
        assert bool(on_arrays[k]) is expected
        assert collides(ca, ma, ga, cb, mb, gb) == collides(cb, mb, gb, ca, ma, ga)  # symmetric


def test_the_broad_phase_drops_filtered_pairs_before_the_narrow_phase():
    from isaac.engine.broad_phase import SWEEP_INDEX_ROWS, find_pairs

    n = 4  # four overlapping unit boxes in a row; 1 and 2 share group -1
    position = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [1.5, 0.0]])
    aabb = np.concatenate([position - 0.5, position + 0.5], axis=1)
    args = dict(
        position=position,
        radius=np.full(n, 0.71),
        aabb=aabb,
        expand=np.zeros(n),
        movable=np.ones(n, dtype=bool),
        exists=np.ones(n, dtype=bool),
        sweeps=np.ones(n, dtype=bool),
        category=np.ones(n, dtype=np.int64),
        mask=np.full(n, 0xFFFFFFFF, dtype=np.int64),
        group=np.array([0, -1, -1, 0], dtype=np.int64),
        no_collide=np.array([2 * n + 3], dtype=np.int64),  # a joint keeps 2 and 3 apart
    )
    scratch = dict(
        pair_a=np.zeros(16, dtype=np.int64),
        pair_b=np.zeros(16, dtype=np.int64),
        pair_spare=np.zeros(16, dtype=np.int64),
        sweep_index=np.zeros((SWEEP_INDEX_ROWS, n + 1), dtype=np.int64),
        sweep_key=np.zeros(n),
        sweep_table=np.zeros((n, 8)),
    )
    found = {}
    for filtered in (False, True):
        count = find_pairs(filtered=filtered, **args, **scratch)
        found[filtered] = list(zip(scratch["pair_a"][:count], scratch["pair_b"][:count]))
    assert (1, 2) in found[False] and (2, 3) in found[False]
    assert found[True] == [p for p in found[False] if p not in ((1, 2), (2, 3))]


def test_colliders_are_the_bodies_some_other_body_may_collide_with():
    """`colliders` by filter classes against the rule tried on every pair of bodies."""
    rng = np.random.default_rng(14)
    for _ in range(200):
        n = int(rng.integers(1, 9))
        category = rng.choice([1, 2, 4], n).astype(np.int64)
        mask = rng.choice([0, 1, 2, 5, 0xFFFFFFFF], n).astype(np.int64)
        group = rng.choice([-2, -1, 0, 0, 1], n).astype(np.int64)
        expected = [
            any(
                bool(collides(category[i], mask[i], group[i], category[j], mask[j], group[j]))
                for j in range(n)
                if j != i
            )
            for i in range(n)
        ]
        assert colliders(category, mask, group).tolist() == expected


def test_bodies_left_out_of_the_sweep_change_no_bit(monkeypatch):
    """Box2D v3's joint grid: every circle in one negative group, so none enters the sweep;
    the run is the one that sweeps them all (and finds no pair)."""
    import isaac.engine.world
    from bench.joint_grid import grid_scene

    scene = grid_scene(6)
    left_out = Simulation(scene)
    assert not left_out.model.sweeps.any()
    monkeypatch.setattr(isaac.engine.world, "colliders", lambda c, m, g: np.ones(len(c), bool))
    swept = Simulation(scene)
    assert swept.model.sweeps.all()
    for sim in (left_out, swept):
        sim.advance(40)  # the net swings down from its seven concrete bodies
        assert len(sim.record().contacts) == 0
    for field in ("position", "angle", "velocity", "angular_velocity"):
        assert np.array_equal(getattr(left_out.state, field), getattr(swept.state, field))


def test_the_shipped_filtering_scene_keeps_its_filtered_pairs_apart():
    scene = load_scene("scenes/filtering.yaml")
    sim = Simulation(scene)
    touching = _pairs_touching(sim, scene.world.steps)
    for apart in [("red_low", "red_high"), ("blue", "ghost"), ("ghost", "ball")]:
        assert apart not in touching
    for together in [("ground", "red_low"), ("ground", "red_high"), ("ground", "ghost")]:
        assert together in touching
    assert ("blue", "ball") in touching
    # the red boxes end in one place, on the ground, overlapping each other
    np.testing.assert_allclose(
        sim.body("red_high").position, sim.body("red_low").position, atol=0.02
    )


def test_a_filter_is_written_to_the_log_text_only_where_it_is_not_the_default():
    scene = load_scene("scenes/filtering.yaml")
    text = scene_to_yaml(scene)
    assert load_scene_text(text, scene.source) == scene
    # red_low, red_high (their group), blue, ghost and ball; not the ground
    assert text.count("    category: ") == 5
    plain = scene_to_yaml(load_scene("scenes/bounce.yaml"))
    assert "category" not in plain and "mask" not in plain and "group" not in plain


@pytest.mark.parametrize(
    "field, message",
    [
        ("mask: -1", "bodies[0].mask: -1 is out of range (must be 0..0xffffffff)"),
        ("category: 0x100000000", "bodies[0].category: 4294967296 is out of range"),
        ("category: 1.5", "bodies[0].category: expected a whole number of 32 bits"),
        ("group: 3000000000", "bodies[0].group: 3000000000 is out of range"),
        ("mask: 0xZZ", "bodies[0].mask: expected a whole number of 32 bits"),
    ],
)
def test_a_bad_filter_is_refused_at_its_key(field, message):
    with pytest.raises(SceneError) as caught:
        load_scene_text(f"bodies:\n  - {{name: c, shape: {{box: [1, 1]}}, {field}}}\n", "f.yaml")
    assert str(caught.value).startswith("f.yaml:2: ")
    assert message in str(caught.value)
