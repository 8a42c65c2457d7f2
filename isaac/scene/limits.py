"""Limits on what a scene may say: every bound the loader checks, in one place.

The scene loader, the generators and the log loader all check against these, so a scene that
`isaac check` accepts is one a log of it can carry. Units are SI (m, s, kg, rad).

Bodies are checked after expansion (isaac.scene.checks): a box, a regular polygon or a body a
generator makes must pass exactly the checks a `polygon:` body passes, because a log stores
every shape as `polygon:` (docs/scene-format.md, "Round trip").
"""

from __future__ import annotations

MAX_VERTICES = 50  # the seed's LocalSpaceList[50][2]
MAX_BODIES = 100_000
MAX_COORDINATE = 1e9  # m: bound on |position| and on |vertex coordinate| (in the body's frame)
MIN_SIZE, MAX_SIZE = 1e-6, 1e6  # m: box sides, regular radius, polygon extent (bbox diagonal),
# circle diameter
MAX_SPEED = 1e6  # m/s and rad/s
MAX_TIME = 1e9  # s: enters_at / leaves_at
MAX_DENSITY = 1e9  # kg/m^2
MAX_FRICTION = 1e3
MAX_STEPS = 100_000_000
MAX_ITERATIONS = 1000
MAX_SUBSTEPS = 1000
MAX_GRAVITY = 1e4  # m/s^2 per component
MAX_NAME_LENGTH = 200
FILTER_BITS = 32  # collision filter: category and mask are whole numbers of this many bits
MAX_GROUP = 2**31 - 1  # collision filter group, in [-MAX_GROUP, MAX_GROUP]
MAX_PYRAMID_ROWS = 446  # 446 * 447 / 2 = 99,681 boxes: the largest pyramid under MAX_BODIES
PILE_CONTAINER_BODIES = 3  # floor, left and right wall
MAX_PILE_COUNT = MAX_BODIES - PILE_CONTAINER_BODIES

# Joints (the `joints:` section, isaac.scene.checks.joint_problem)
MAX_JOINTS = 100_000
# m: each coordinate of an anchor in its body's frame: a world point within MAX_COORDINATE of
# the origin seen from a body centre also within it is at most 2 * sqrt(2) * 1e9 m away
MAX_ANCHOR = 3e9
MAX_JOINT_LENGTH = 1e10  # m: distance joints' lengths, prismatic limits along the axis
MAX_REFERENCE_ANGLE = 2 * MAX_SPEED  # rad: the difference of two body angles
MIN_AXIS = 1e-9  # a prismatic axis shorter than this gives no direction
AXIS_TOLERANCE = 1e-12  # a stored axis is unit: | |axis| - 1 | <= this
# a distance joint's anchors at step 0 coincide when they are at most this share of the largest
# coordinate involved (m, at least 1 m) apart: about 450 float64 roundings, far more than a
# world point turned into a body's frame and back loses, far less than any gap meant
COINCIDENT_ANCHORS = 1e-13
MAX_STIFFNESS = 1e6  # Hz
MAX_DAMPING_RATIO = 1e3
MAX_MOTOR_TORQUE = 1e15  # N m
MAX_MOTOR_FORCE = 1e15  # N

# Input size. A scene text in the exact form `scene_to_yaml` writes (what a log stores) is read
# by a line reader that builds no YAML node tree (isaac.scene.fast_reader), in time and memory
# linear in its size: up to MAX_SCENE_BYTES, the text of 100,000 bodies of 50 vertices (about
# 230 MB). Any other YAML goes through a node tree (memory and time per node), bounded
# by bytes, nodes, list length and nesting, so hostile input is refused in seconds and a few
# hundred MB: MAX_YAML_NODES is 30 nodes for each of MAX_BODIES bodies (a hand-written body
# with a name, a box, a position and a velocity is about 15).
MAX_SCENE_BYTES = 256 * 1024 * 1024
MAX_YAML_BYTES = 64 * 1024 * 1024
MAX_YAML_NODES = 30 * MAX_BODIES
MAX_BODY_NODES = 200  # a body of MAX_VERTICES vertices with every key given has 181
MAX_SECTION_NODES = 100_000  # under `world:`, `generators:`, `joints:`, `analytic:` (not `bodies:`)
MAX_LIST_ITEMS = MAX_BODIES  # the longest list a scene has is `bodies:`
MAX_NESTING = 32  # a scene nests 7 deep, `analytic:` at most 17
MAX_QUOTED = 60  # characters of a value or key quoted in an error message
