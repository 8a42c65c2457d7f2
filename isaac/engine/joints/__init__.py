"""Joints: revolute, distance, weld and prismatic constraints, solved with the contacts.

One module per joint kind, as Box2D v3 keeps revolute_joint.c, distance_joint.c, weld_joint.c
and prismatic_joint.c apart from joint.c:
- `joint`: the joint table (`Joints`, `joint_table`, `in_waves`) and the per-joint loops of
  each phase (prepare, warm start, velocity pass, position passes and errors, the impulses
  kept and the rows written), which dispatch on the kind;
- `revolute`, `weld`, `distance`, `prismatic`: each kind's prepare, velocity, warm start,
  position, error and reaction parts, their formulas and sources in the module docstrings
  (the weld uses the revolute's point constraint);
- `shared`: the scratch row's columns, the correction caps, and the arithmetic the kinds share.
Every step the sequential solver (isaac.engine.solver.sequential) and the step's stages
(isaac.engine.step, isaac.engine.driver) call the phases in `joint`'s order. Imports the
engine's geometry, its integration constants and kernel_cache (and numba, numpy).
"""

from isaac.engine.joints.joint import (
    Joints,
    correct_joint_positions,
    in_waves,
    joint_table,
    keep_joint_impulses,
    prepare_joints,
    solve_joint_velocities,
    warm_start_joints,
    write_joint_rows,
)
from isaac.engine.joints.shared import JOINT_IMPULSES, WIDTH

__all__ = [
    "JOINT_IMPULSES",
    "WIDTH",
    "Joints",
    "correct_joint_positions",
    "in_waves",
    "joint_table",
    "keep_joint_impulses",
    "prepare_joints",
    "solve_joint_velocities",
    "warm_start_joints",
    "write_joint_rows",
]
