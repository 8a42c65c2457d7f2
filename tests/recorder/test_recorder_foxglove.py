"""The optional Foxglove channel decodes with its stored schema into the expected scene."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from test_recorder_mcap import generic_messages, record_run  # noqa: E402


def test_foxglove_scene_update_holds_outlines_and_contact_arrows(tmp_path):
    path = tmp_path / "fg.mcap"
    sim, records = record_run(path, n=8, contacts=5, steps=20, foxglove=True, leave_at=10)
    msgs = [(raw, m) for t, raw, m in generic_messages(path) if t == "/foxglove/scene"]
    assert len(msgs) == len(records)
    model = sim.model
    for (raw, update), r in zip(msgs, records):
        assert raw.sequence == r.step
        assert type(update).DESCRIPTOR.full_name == "foxglove.SceneUpdate"
        bodies, contacts = update.entities
        assert bodies.id == "bodies" and bodies.frame_id == "world"
        assert bodies.timestamp.seconds * 10**9 + bodies.timestamp.nanos == raw.log_time
        line = bodies.lines[0]
        assert line.type == 2  # LINE_LIST
        edges = int(np.sum(model.vertex_count[r.exists]))
        assert len(line.points) == 2 * edges
        # first edge of the first existing body: vertex 0 in world coordinates
        k = int(np.flatnonzero(r.exists)[0])
        c, s = np.cos(r.angle[k]), np.sin(r.angle[k])
        v = model.vertices_local[k, 0]
        expected = r.position[k] + np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])
        np.testing.assert_allclose([line.points[0].x, line.points[0].y], expected, rtol=1e-12)
        normals, impulses = contacts.lines
        assert len(normals.points) == len(impulses.points) == 2 * len(r.contacts)
        if len(r.contacts):
            np.testing.assert_array_equal(
                [normals.points[0].x, normals.points[0].y], r.contacts.point[0]
            )
