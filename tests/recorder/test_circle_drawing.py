"""Circles in the log and the viewers: `/world` carries each circle's radius, the log's table
reads it back, and both viewers draw a ring with a spoke that turns with the body."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from isaac.engine.simulation import Simulation
from isaac.scene import load_scene
from recorder import Recorder
from recorder.reader import LogReader
from recorder.rerun_writer import mcap_to_rrd
from recorder.shapes import CIRCLE_SIDES, circle_radii, drawn_shapes

ROOT = Path(__file__).resolve().parents[2]


def test_a_circles_radius_goes_through_the_log_and_is_drawn_as_a_ring(tmp_path):
    sim = Simulation(load_scene(ROOT / "scenes" / "rolling.yaml"))
    log = tmp_path / "rolling.mcap"
    with Recorder(sim, mcap_path=str(log)) as rec:
        for record in sim.run(30):
            rec.write(record)
    table = LogReader(str(log)).world
    disc = table.names.index("disc")
    assert table.circle_radius.tolist() == [0.0, 0.5, 0.0]
    assert table.vertex_count[disc] == 1
    np.testing.assert_array_equal(circle_radii(table), circle_radii(sim.model))
    local, counts = drawn_shapes(table)
    assert counts[disc] == CIRCLE_SIDES + 1
    ring = local[disc, 1 : CIRCLE_SIDES + 1]
    np.testing.assert_allclose(np.hypot(ring[:, 0], ring[:, 1]), 0.5, rtol=1e-12)
    assert local[disc, 0].tolist() == [0.0, 0.0]  # the spoke starts at the centre
    # the polygons are drawn as they are
    box = table.names.index("box")
    np.testing.assert_array_equal(local[box, :4], table.vertices_local[box, :4])
    rrd = mcap_to_rrd(str(log), str(tmp_path / "rolling.rrd"))
    assert Path(rrd).stat().st_size > 0
