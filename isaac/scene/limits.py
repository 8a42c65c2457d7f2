"""Limits on what a scene may say: every bound the loader checks, in one place.

The scene loader, the generators and the log loader all check against these, so a scene that
`isaac check` accepts is one a log of it can carry. Units are SI (m, s, kg, rad).
"""

from __future__ import annotations

MAX_VERTICES = 50  # the seed's LocalSpaceList[50][2]
MAX_BODIES = 100_000
MAX_SCENE_BYTES = 256 * 1024 * 1024  # a 100,000-body expanded scene is about 60 MB
MAX_COORDINATE = 1e9  # m: |position| and |vertex coordinate| bound (float64 keeps 1e-7 m there)
MIN_SIZE, MAX_SIZE = 1e-6, 1e6  # m: box sides, regular radius, polygon extent
MAX_SPEED = 1e6  # m/s and rad/s
MAX_TIME = 1e9  # s: enters_at / leaves_at
MAX_DENSITY = 1e9  # kg/m^2
MAX_FRICTION = 1e3
MAX_STEPS = 100_000_000
MAX_ITERATIONS = 1000
MAX_SUBSTEPS = 1000
MAX_GRAVITY = 1e4  # m/s^2 per component
MAX_NAME_LENGTH = 200
MAX_PYRAMID_ROWS = 446  # 446 * 447 / 2 = 99,681 boxes: the largest pyramid under MAX_BODIES
