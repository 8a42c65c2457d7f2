"""First recorded run on a machine: the recorder's kernels compiled in a helper process beside
the engine's.

With an empty numba cache, `isaac run SCENE --mcap A --rrd B` compiled the engine's kernels
(about 17-20 s on the 2-core machine, `isaac.engine.compile_ahead`) and then, in the same
process and one after the other (numba compiles under one lock a process), the recorder's
packers and drawers: about 24 s more, `recorder.mcap_pack.pack_records` 13.7 s of it, most of
that after the last step, while the files were finished (43 s in all, 2026-12-03). `start`
runs `python -m recorder.compile_ahead` as soon as the scene is read: it records two steps of a
two-box world through `Recorder`, as `isaac run` records (the writer thread, the Rerun drawing,
read-only batches), into a temporary folder it deletes, so that numba writes the very kernels
the run calls into the on-disk cache. `isaac run` compiles the engine's meanwhile (the driver
in the solver's helper, `isaac.engine.compile_ahead.prepare`, or, when that is not at work,
here: `compile_driver`), then waits for the helper (`finish`) and loads the recorder's kernels
from the cache. Nothing here changes what is recorded; if the
helper cannot start or fails, the run compiles what the cache lacks itself, as it would without
it. A warm cache (`cold` False) starts nothing.

This module imports the standard library only until `cold` is called (which imports numba).
"""

from __future__ import annotations

import os
import pickle
import sys


def cold(mcap: bool, rrd: bool) -> bool:
    """Whether numba's cache lacks the recorder's longest compiles for these files (MCAP:
    `pack_records`; Rerun: `draw_steps`)."""
    from isaac.engine.compile_ahead import is_cold

    kernels = []
    if mcap:
        from recorder.mcap_pack import pack_records

        kernels.append(pack_records)
    if rrd:
        from recorder.rerun_batch import draw_steps

        kernels.append(draw_steps)
    return any(is_cold(k) for k in kernels)


def start(world, *, mcap: bool, rrd: bool, joints: bool):
    """`python -m recorder.compile_ahead` compiling the kernels of these files for a scene with
    `world`'s settings (`joints`: the scene has joints); or None when it cannot start
    (`isaac.engine.compile_ahead.start_helper`)."""
    from isaac.engine.compile_ahead import start_helper

    return start_helper("recorder.compile_ahead", [], (world, bool(mcap), bool(rrd), bool(joints)))


def finish(proc) -> None:
    """Wait for the helper `start` returned (`isaac.engine.compile_ahead.wait_helper`: Ctrl-C or
    a failure kills it first)."""
    from isaac.engine.compile_ahead import wait_helper

    wait_helper(proc)


class _TwoBoxRun:
    """What `Recorder` reads of a `Simulation`, for two boxes at rest (the lower one concrete)
    under `world`'s settings: the model, the scene, step 0's record; and `batch`, steps 1 and 2
    as the compiled driver hands them (`StepBatch`: read-only arrays of the driver's dtypes)."""

    def __init__(self, world, *, joints: bool) -> None:
        from isaac.engine.compile_ahead import _SmallWorld
        from isaac.engine.driver import Stepper
        from isaac.engine.records import CONTACT_FIELDS, StepBatch

        small = _SmallWorld(world, joint=joints)
        self.model, self.scene, self.step_index = small.model, small.scene, 0
        arrays = Stepper(small.model, small.settings, small.dt, small.work).new_batch(2)
        position, angle, velocity, angular_velocity, exists = arrays[:5]
        position[:] = small.state.position
        angle[:] = small.state.angle
        velocity[:] = 0.0
        angular_velocity[:] = 0.0
        exists[:] = True
        joint_arrays = arrays[6 + len(CONTACT_FIELDS) :]  # (steps, m, ...): none, or the hinge
        for joint_array in joint_arrays:  # at rest
            joint_array[:] = 0.0
        self._start = StepBatch(0, small.dt, tuple(a.copy() for a in arrays), 1).record(0)
        self.batch = StepBatch(1, small.dt, arrays, 2)

    def record(self):
        return self._start


def compile_kernels(world, *, mcap: bool, rrd: bool, joints: bool) -> None:
    """The helper's work: two steps recorded as `isaac run` records them (the MCAP writer's
    thread; the Rerun drawing in this process, sent by a sender in it too), into a temporary
    folder that is deleted after."""
    import tempfile

    from recorder import Recorder

    run = _TwoBoxRun(world, joints=joints)
    with tempfile.TemporaryDirectory(prefix="isaac-recorder-compile-") as tmp:
        with Recorder(
            run,
            mcap_path=os.path.join(tmp, "run.mcap") if mcap else None,
            rrd_path=os.path.join(tmp, "run.rrd") if rrd else None,
            offload="thread",
        ) as rec:
            rec.write_batch(run.batch)


if __name__ == "__main__":
    world, mcap, rrd, joints = pickle.load(sys.stdin.buffer)
    compile_kernels(world, mcap=mcap, rrd=rrd, joints=joints)
