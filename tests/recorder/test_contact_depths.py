"""The two depths of a logged contact mean what docs/log-format.md says, checked from the log
alone against an independent separating-axis test (numpy, here).

- ``pair_depth`` (per manifold) is the pair's MTD depth before the push-out: the overlap of the
  two polygons, at the poses logged on the step before, along the logged normal; without axis
  hysteresis that normal is the SAT's minimum axis, so ``pair_depth`` is the SAT's MTD.
- ``point_depth`` (per point) is how far that point lay behind the reference face (the feature's
  ref side and edge), along the face's outward normal, before the push-out moved its body.

Logs are decoded with google.protobuf from the descriptor set stored in the file.
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

ROOT = Path(__file__).resolve().parents[2]
STEPS = 240  # the first bodies land and pile up by then


def _world(local, position, angle):
    c, s = np.cos(angle), np.sin(angle)
    return position + local @ np.array([[c, s], [-s, c]])


def _edge_normals(poly):
    """Outward unit normals of a CCW polygon's edges (edge i from vertex i to i + 1)."""
    e = np.roll(poly, -1, axis=0) - poly
    n = np.stack([e[:, 1], -e[:, 0]], axis=1)
    return n / np.linalg.norm(n, axis=1)[:, None]


def _sat(pa, pb):
    """The MTD depth of two convex polygons: minus the largest separation over both polygons'
    edge normals (negative: the gap between polygons apart)."""
    best = -np.inf
    for p, q in ((pa, pb), (pb, pa)):
        for i, n in enumerate(_edge_normals(p)):
            best = max(best, float(np.min((q - p[i]) @ n)))
    return -best


def _logged(tmp_path, hysteresis: bool):
    text = (ROOT / "scenes" / "default.yaml").read_text()
    setting = f"  axis_hysteresis: {str(hysteresis).lower()}\n"
    text = text.replace("  friction: true\n", "  friction: true\n" + setting, 1)
    scene = load_scene_text(text, "<default>")
    assert scene.world.axis_hysteresis is hysteresis and scene.world.substeps == 1
    sim = Simulation(scene)
    path = tmp_path / "default.mcap"
    with Recorder(sim, mcap_path=str(path)) as rec:
        rec.write(sim.record())
        for batch in sim.batches(STEPS, size=40):
            rec.write_batch(batch)
    msgs = generic_messages(path)
    world = [m for t, _, m in msgs if t == "/world"][0]
    local = [np.array(b.vertices_local).reshape(-1, 2) for b in world.bodies]
    bodies = {m.step: m for t, _, m in msgs if t == "/bodies"}
    contacts = [m for t, _, m in msgs if t == "/contacts"]
    return local, bodies, contacts


def _manifolds(local, bodies, contacts):
    """(pa, pb, normal, pair_depth, [(point before the push, point_depth)], ref side, ref edge,
    (a, b)) of every logged manifold, the polygons at the poses the narrow phase saw (those
    logged on the step before)."""
    for c in contacts:
        if not len(c.a):
            continue
        before = bodies[c.step - 1]
        pos = np.array(before.position).reshape(-1, 2)
        ang = np.array(before.angle)
        normal = np.array(c.normal).reshape(-1, 2)
        # the pushes are stored for the manifolds the push-out moved (`pushed`) only
        push_a = np.zeros((len(c.a), 2))
        push_b = np.zeros((len(c.a), 2))
        moved = np.array(c.pushed, dtype=np.int64)
        push_a[moved] = np.array(c.push_a).reshape(-1, 2)
        push_b[moved] = np.array(c.push_b).reshape(-1, 2)
        point = np.array(c.point).reshape(-1, 2)
        at = 0
        for j in range(len(c.a)):
            a, b = c.a[j], c.b[j]
            side, edge = c.feature[j] // 4096, (c.feature[j] // 64) % 64
            # the points lie on the incident body and moved with its push
            moved = push_b[j] if side == 0 else push_a[j]
            pts = [(point[at + q] - moved, c.point_depth[at + q]) for q in range(c.points[j])]
            at += c.points[j]
            yield (
                _world(local[a], pos[a], ang[a]),
                _world(local[b], pos[b], ang[b]),
                normal[j],
                c.pair_depth[j],
                pts,
                side,
                edge,
                (a, b),
            )


@pytest.fixture(scope="module")
def no_hysteresis(tmp_path_factory):
    return _logged(tmp_path_factory.mktemp("depths"), hysteresis=False)


def test_the_logged_pair_depth_is_the_sat_mtd_of_the_poses_before(no_hysteresis):
    face_face = 0
    worst = 0.0
    for pa, pb, n, pair_depth, pts, _side, _edge, _ab in _manifolds(*no_hysteresis):
        mtd = _sat(pa, pb)
        worst = max(worst, abs(pair_depth - mtd))
        # along the logged normal too: a's extent past b's start
        assert pair_depth == pytest.approx(float(np.max(pa @ n) - np.min(pb @ n)), abs=1e-12)
        face_face += len(pts) == 2
    assert worst <= 1e-12
    assert face_face >= 200  # two-point (face-face) manifolds among them


def test_the_logged_point_depth_is_the_points_own_penetration(no_hysteresis):
    shallower = 0
    for pa, pb, n, pair_depth, pts, side, edge, _ab in _manifolds(*no_hysteresis):
        ref = pa if side == 0 else pb
        out = n if side == 0 else -n  # the reference face's outward normal
        np.testing.assert_allclose(_edge_normals(ref)[edge], out, atol=1e-12)
        for p, point_depth in pts:
            assert point_depth == pytest.approx(float(-(p - ref[edge]) @ out), abs=1e-12)
            # never deeper than the pair's MTD: the deepest incident vertex may be clipped away
            assert point_depth <= pair_depth + 1e-12
            shallower += point_depth < pair_depth - 1e-6
    assert shallower >= 50  # the two depths do differ: a point is not the pair's MTD


def test_with_axis_hysteresis_the_pair_depth_is_the_overlap_along_the_kept_axis(tmp_path):
    """Axis hysteresis keeps last step's face while it is within 2 % of the depth plus 1e-4 of
    the smaller body's radius of the best one (isaac.engine.narrow_phase): the logged pair depth
    is then the overlap along that kept normal, a little more than the SAT's minimum."""
    local, bodies, contacts = _logged(tmp_path, True)
    radius = [float(np.linalg.norm(p, axis=1).max()) for p in local]  # about the CoM
    kept = 0
    for pa, pb, n, pair_depth, _pts, _side, _edge, (a, b) in _manifolds(local, bodies, contacts):
        along = float(np.max(pa @ n) - np.min(pb @ n))
        assert pair_depth == pytest.approx(along, abs=1e-12)
        mtd = _sat(pa, pb)
        assert pair_depth >= mtd - 1e-12  # the MTD axis overlaps least
        assert pair_depth <= mtd + 0.02 * abs(mtd) + 1e-4 * min(radius[a], radius[b]) + 1e-12
        kept += pair_depth > mtd + 1e-12
    assert kept >= 1  # some faces were kept over the minimum axis
