"""Inputs at the edges of the scene contract: scenes whose arrays of polygons, pairs or joints
are empty, distance joints with no line to act along, and the YAML rules the docs state (null
only where allowed, a quoted value always a string, anchors named in a sweep file)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

from isaac.errors import SceneError
from isaac.scene import load_scene_text
from isaac.scene.checks import first_joint_problem, joint_problem
from isaac.scene.joints import to_body_frame
from isaac.scene.spec import JointSpec
from isaac.scene.warnings import scene_warnings

ROOT = Path(__file__).resolve().parents[1]


def _isaac(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "isaac", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )


# --- scenes whose arrays are empty -------------------------------------------------------------

W = "world: {dt: 0.01, steps: 5}\nbodies:\n"
EDGE_SCENES = {
    "two circles": W + "  - {name: a, shape: {circle: {radius: 0.5}}}\n"
    "  - {name: b, shape: {circle: {radius: 0.5}}, position: [2, 0]}\n",
    "overlapping circles": W + "  - {name: a, shape: {circle: {radius: 0.5}}}\n"
    "  - {name: b, shape: {circle: {radius: 0.5}}, position: [0.5, 0]}\n",
    "one circle": W + "  - {name: a, shape: {circle: {radius: 0.5}}}\n",
    "one box": W + "  - {name: a, shape: {box: [1, 1]}}\n",
    "only concrete": W + "  - {name: a, shape: {box: [1, 1]}, concrete: true}\n"
    "  - {name: b, shape: {circle: {radius: 0.5}}, position: [0.2, 0], concrete: true}\n",
    "polygons, no circles": W + "  - {name: a, shape: {box: [1, 1]}}\n"
    "  - {name: b, shape: {regular: {sides: 5, radius: 0.5}}, position: [0.5, 0]}\n",
    "pendulum on a circle pivot": W
    + "  - {name: pivot, shape: {circle: {radius: 0.1}}, position: [0, 2], concrete: true}\n"
    "  - {name: bob, shape: {circle: {radius: 0.1}}, position: [1, 2]}\n"
    "joints:\n  - {type: distance, bodies: [pivot, bob], anchor_a: [0, 2], anchor_b: [1, 2]}\n",
    "all enter later": W + "  - {name: a, shape: {circle: {radius: 0.5}}, enters_at: 0.02}\n"
    "  - {name: b, shape: {circle: {radius: 0.5}}, position: [0.5, 0], enters_at: 0.03}\n",
    "none ever exists": W + "  - {name: a, shape: {circle: {radius: 0.5}}, enters_at: 10}\n"
    "  - {name: b, shape: {box: [1, 1]}, leaves_at: 0.001, enters_at: 0.0005}\n",
}


def test_a_scene_of_circles_alone_warns_with_the_circles_overlap():
    assert scene_warnings(load_scene_text(EDGE_SCENES["two circles"])) == []
    (line,) = scene_warnings(load_scene_text(EDGE_SCENES["overlapping circles"]))
    assert "'a' and 'b' by 0.5 m" in line  # r1 + r2 - d = 0.5 + 0.5 - 0.5


@pytest.mark.parametrize("name", sorted(EDGE_SCENES))
def test_edge_scenes_check_run_and_record_from_the_command_line(name, tmp_path):
    scene = tmp_path / "edge.yaml"
    scene.write_text(EDGE_SCENES[name])
    done = _isaac("check", str(scene))
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    mcap, rrd = tmp_path / "edge.mcap", tmp_path / "edge.rrd"
    done = _isaac("run", str(scene), "--quiet", "--mcap", str(mcap), "--rrd", str(rrd))
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert mcap.stat().st_size > 0 and rrd.stat().st_size > 0


def test_a_sweep_of_a_scene_of_circles_alone_runs(tmp_path):
    (tmp_path / "circles.yaml").write_text(EDGE_SCENES["overlapping circles"])
    sweep = tmp_path / "circles.sweep.yaml"
    sweep.write_text("scene: circles.yaml\nruns:\n  grid:\n    world.dt: [0.01, 0.005]\n")
    out = tmp_path / "out"
    done = _isaac("sweep", str(sweep), "-o", str(out), "--workers", "1", "--quiet", "--no-plots")
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert (out / "runs.parquet").exists()


# --- distance joints whose anchors coincide at step 0 ------------------------------------------

FREE = """\
world: {gravity: [0, 0]}
bodies:
  - {name: a, shape: {box: [0.2, 0.2]}, position: [0, 0], angle: 0.3}
  - {name: b, shape: {box: [0.2, 0.2]}, position: [1, 0], angle: -1.1}
"""


def test_a_rigid_distance_joint_with_coincident_anchors_is_refused_in_one_line(tmp_path):
    scene = tmp_path / "rod.yaml"
    scene.write_text(
        FREE + "joints:\n  - type: distance\n    bodies: [a, b]\n"
        "    anchor_a: [0.5, 0]\n    anchor_b: [0.5, 0]\n    length: 0.5\n"
    )
    done = _isaac("check", str(scene))
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.splitlines()
    assert line.startswith(f"isaac check: error: {scene}:9: joints[0].anchor_b: ")
    assert "anchors coincide at step 0" in line and "revolute joint" in line


@pytest.mark.parametrize(
    "options", [dict(), dict(stiffness=2.0), dict(max_length=0.6), dict(min_length=0.1)]
)
def test_a_python_built_distance_joint_with_coincident_anchors_is_refused(options):
    bodies = load_scene_text(FREE).bodies
    point = (0.5, 0.0)  # one world point, turned into each body's frame (rounding apart)
    joint = JointSpec(
        "rod",
        "distance",
        0,
        1,
        to_body_frame(bodies[0], point),
        to_body_frame(bodies[1], point),
        length=0.5,
        **options,
    )
    why = joint_problem(bodies, joint)
    assert why is not None and why[0] == "local_b" and "coincide" in why[1], why
    assert first_joint_problem(bodies, [joint]).field == "local_b"
    apart = dataclasses.replace(joint, local_b=to_body_frame(bodies[1], (0.5, 1e-9)))
    assert joint_problem(bodies, apart) is None


# --- YAML rules: null, quoted values, anchors in a sweep file ----------------------------------

BOX = "  - {shape: {box: [1, 1]}}\n"


@pytest.mark.parametrize(
    "text, line, path",
    [
        ("bodies:\n" + BOX + "joints: null\n", 3, "joints"),
        ("bodies:\n" + BOX + "joints:\n", 3, "joints"),
        ("world: ~\nbodies:\n" + BOX, 1, "world"),
        ("analytic: null\nbodies:\n" + BOX, 1, "analytic"),
        ("bodies:\n" + BOX + "generators: null\n", 3, "generators"),
        ("bodies: null\ngenerators:\n  - pyramid: {rows: 1, box: [1, 1]}\n", 1, "bodies"),
    ],
)
def test_a_null_section_is_refused_at_its_key(text, line, path):
    with pytest.raises(SceneError) as caught:
        load_scene_text(text, source="s.yaml")
    e = caught.value
    assert (e.line, e.path) == (line, path), str(e)
    assert "got null" in e.what and f"leave `{path}:` out" in e.what


def test_null_inside_analytic_is_refused_and_where_the_docs_allow_it_accepted():
    with pytest.raises(SceneError, match=r"analytic\.model: null is not allowed"):
        load_scene_text("analytic: {model: null}\nbodies:\n" + BOX)
    scene = load_scene_text("bodies:\n  - {shape: {box: [1, 1]}, leaves_at: null}\n")
    assert scene.bodies[0].leaves_at is None
    load_scene_text("generators:\n  - pile: {count: 2, container: {height: ~}}\n")


@pytest.mark.parametrize(
    "key, quoted, plain, value",
    [
        ("category", "'0x2'", "0x2", 2),
        ("category", '"5"', "5", 5),
        ("mask", "'0xFF'", "0xFF", 255),
        ("enters_at", "'1/4'", "1/4", 0.25),
        ("restitution", "'0.5'", "0.5", 0.5),
        ("concrete", "'true'", "true", True),
    ],
)
def test_a_quoted_value_is_a_string_wherever_it_is(key, quoted, plain, value):
    body = "bodies:\n  - {{shape: {{box: [1, 1]}}, {}: {}}}\n"
    with pytest.raises(SceneError) as caught:
        load_scene_text(body.format(key, quoted), source="s.yaml")
    e = caught.value
    assert e.path == f"bodies[0].{key}" and "quoted, so a string" in e.what, str(e)
    assert getattr(load_scene_text(body.format(key, plain)).bodies[0], key) == value


def test_a_quoted_fraction_in_world_is_refused():
    with pytest.raises(SceneError, match=r"world\.dt: .*'1/120' \(quoted, so a string"):
        load_scene_text("world: {dt: '1/120'}\nbodies:\n" + BOX)


def test_a_yaml_anchor_in_a_sweep_file_is_refused_naming_the_sweep_file(tmp_path):
    (tmp_path / "s.yaml").write_text("bodies:\n" + BOX)
    sweep = tmp_path / "s.sweep.yaml"
    sweep.write_text(
        "scene: s.yaml\nruns:\n  grid:\n    world.dt: &dt [0.01, 0.005]\n    world.slop: *dt\n"
    )
    done = _isaac("sweep", str(sweep), "-o", str(tmp_path / "out"))
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.splitlines()
    assert line.endswith(f"{sweep}:4: YAML anchors (&name) are not allowed in a sweep file")
