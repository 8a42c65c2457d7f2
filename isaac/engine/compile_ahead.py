"""First run on a machine: compile the step's kernels in two processes at once.

With an empty numba cache the first step compiles every kernel it reaches, one after the other,
in this process: about 14 s on the 2-core benchmark machine, over half of it the impulse solver
(`isaac.engine.solver.sequential.solve_sequential` and the kernels it calls, ~7.8 s; detection,
push-out and integration make up the rest). `prepare` splits that work: a helper process compiles
the solver into the on-disk cache while this process compiles the other stages, then this process
waits for the helper and loads the solver from the cache at its first call.

Both sides compile by running the stages on a two-box scene with the simulation's own world
settings (built from the stages' own pieces, not through `Simulation`, which calls this): numba
specialises on argument types only (dtypes, dimensions, layouts), never on sizes or values, so the
kernels compiled for the small scene are the ones the real scene calls. Nothing here changes what a
step computes; if the helper cannot start or fails, this process compiles the solver itself, as it
would without it. A warm cache (the solver's index file exists) skips all of this.

Tiered (`prepare(tiered=True)`, what `isaac run` asks for): the compiled driver, which links every
stage and compiles on one core for 7.6-9.5 s after them (numba optimises and generates the linked
stages' code again inside it), is compiled by the solver's helper once this process says the
other stages are cached, while this process steps on the staged path. A first `isaac run` of the
default scene: its first step 8.2-10.4 s after the start, against 15.5-19.1 s when it waited for
the driver; 15.7-20.5 s in all, against 15.8-19.4 s (bench/README.md, "Night").
"""

from __future__ import annotations

import os
import pickle
import sys
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import subprocess

HELPER_TIMEOUT_S = 300.0  # a helper that takes longer is killed; this process compiles instead

_BOX = ((-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5))


def solver_kernel(settings):
    """The compiled solver `isaac.engine.solver.solve_contacts` dispatches to for these settings."""
    from isaac.engine.solver import seed, sequential

    return seed.solve_seed if settings.seed_solver else sequential.solve_sequential


def is_cold(kernel) -> bool:
    """True when numba has no cache index for `kernel` yet (its first call would compile it).

    False without a cache to look at (NUMBA_DISABLE_JIT, cache off): nothing to do then.
    """
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    index = getattr(cache_file, "_index_path", None)
    return index is not None and not os.path.exists(index)


class _SmallWorld:
    """Two overlapping 1 m boxes (the lower one concrete) under `world`'s settings, as the step's
    stages take them."""

    def __init__(self, world, *, joint: bool = False) -> None:
        """joint: the box hangs from the floor by a revolute joint (for the joints' kernels)."""
        from isaac.engine.joints import JOINT_IMPULSES
        from isaac.engine.records import Contacts
        from isaac.engine.step import ContactCache, StepSettings, Workspace
        from isaac.engine.world import build_model, initial_state
        from isaac.scene import BodySpec, Scene
        from isaac.scene.spec import JointSpec

        hinge = JointSpec(
            name="hinge", kind="revolute", a=0, b=1, local_a=(0.0, 0.5), local_b=(0.0, -0.45)
        )
        scene = Scene(
            name="compile-ahead",
            world=world,
            bodies=(
                BodySpec(name="floor", vertices=_BOX, concrete=True),
                BodySpec(name="box", vertices=_BOX, position=(0.0, 0.95)),
            ),
            joints=(hinge,) if joint else (),
        )
        self.dt = world.dt
        self.scene = scene
        self.model = build_model(scene)
        self.settings = StepSettings.of(world)
        self.state = initial_state(scene, self.model)
        self.work = Workspace(self.model)
        joints = self.model.joints.kind.shape[0]  # the hinge's warm-start impulses, or none
        self.cache = ContactCache.of(
            Contacts.empty(), self.model.n_bodies, np.zeros((joints, JOINT_IMPULSES))
        )


WAITING: list = []  # helpers compiling what only the driver needs (the joints' kernels)


def joints_kernel():
    """A kernel of the joints' the driver calls (`prepare_joints`; the others are compiled with
    it): cold means the joints' helper has work to do."""
    from isaac.engine.joints import prepare_joints

    return prepare_joints


def driver_kernel(settings, *, joints: bool = False, timed: bool = False):
    """The compiled driver a simulation with these StepSettings calls (`joints`: its scene has
    joints; `timed`: `--profile`'s)."""
    from isaac.engine.driver import driver_kernel as kernel

    return kernel(bool(settings.seed_solver), joints, timed)


def prepare(settings, world, joints: bool = False, *, tiered: bool = False):
    """Before the first step of a simulation with these StepSettings and WorldSettings: if the
    solver is not in numba's cache, compile it in a helper process while this one compiles the
    other stages (see the module docstring); and for a scene with joints (`joints`) whose
    joints' kernels are not in it either, compile them in a second helper, which `finish` waits
    for before the driver's first call. A scene without joints never compiles them: its driver
    and solver are specialisations without the joints' code (`isaac.engine.driver`).

    tiered: when the (untimed) driver is not in the cache either, the solver's helper goes on to
    compile the driver once this process has compiled its share (`_compile_driver_when_told`),
    rather than this process at the driver's first call, and is returned (else None): the
    caller steps on the staged path, whose kernels are ready first, until the helper is done
    (`Simulation(tiered=True)`, `isaac run`; registered to be waited for at exit, so that a run
    shorter than the compile leaves no process behind and the next run finds the driver)."""
    jointed_cold = joints and is_cold(joints_kernel())
    driver_cold = tiered and is_cold(driver_kernel(settings, joints=joints))
    kind = ("driver" if driver_cold else "solver") + ("-joints" if joints else "")
    if not is_cold(solver_kernel(settings)) and not jointed_cold:
        if not driver_cold:
            return None
        helper = _start_helper(world, kind, talks=True)
        if helper is not None:
            release(helper)
        return helper
    if jointed_cold and not WAITING:
        joints_helper = _start_helper(world, "joints")
        if joints_helper is not None:
            WAITING.append(joints_helper)
    helper = _start_helper(world, kind, talks=driver_cold)
    if helper is None:
        return None
    try:
        from isaac.engine.integrate import diverged_body
        from isaac.engine.step import step

        small = _SmallWorld(world)
        step(
            small.model, small.settings, small.dt, small.state, small.work, small.cache, solve=False
        )
        diverged_body(small.state)
        _compile_driver_helpers(small)
        if not driver_cold:
            wait_helper(helper)
            return None
        if not _solver_ready(helper):
            return None  # (it failed: the solver and the driver compile at their first calls)
        finish()  # the staged path calls the joints' kernels too, and the driver links them
    except BaseException:  # Ctrl-C or a failure here: no orphan left
        stop_helper(helper)
        raise
    release(helper)
    return helper


def _solver_ready(helper: subprocess.Popen) -> bool:
    """Wait for a driver's helper to say the solver is in the cache (`READY` on its standard
    output). False when it exits first or takes longer than HELPER_TIMEOUT_S (it is then
    stopped)."""
    import select

    with helper.stdout:
        readable, _, _ = select.select([helper.stdout], [], [], HELPER_TIMEOUT_S)
        if readable and helper.stdout.read(len(READY)) == READY:
            return True
    stop_helper(helper)
    return False


def release(helper: subprocess.Popen) -> None:
    """Tell a driver's helper that every stage the driver links is in the cache (`GO` on its
    standard input): it would compile them again otherwise. From then on it is waited for at
    exit at the latest (`wait_helper`)."""
    import atexit

    atexit.register(wait_helper, helper)
    try:
        with helper.stdin:
            helper.stdin.write(GO)
    except OSError:  # it has exited (a failure: the driver compiles at its first call)
        pass


def _compile_driver_helpers(small) -> None:
    """The driver's own small kernels (`isaac.engine.driver`: undo copies, carried contacts,
    existence, batch states), on the bundles a `Stepper` of the small world passes, so that the
    driver's compile, which runs on one core after the helper is done, loads them from the
    cache instead of compiling them. (Its batch rows, `keep_rows`, are the solver's helper's:
    `_compile_row_keeping`, which balances the two processes' shares.)"""
    from isaac.engine import driver

    model, state = small.model, small.state
    stepper = driver.Stepper(model, small.settings, small.dt, small.work)
    pose = (state.position, state.angle, state.velocity, state.angular_velocity, state.exists)
    saved = tuple(a.copy() for a in pose)
    driver._copy_pose(pose, saved)
    driver._copy_carry(stepper.carry, stepper.saved_carry, 0)
    driver.carry_over(stepper.scratch, 0, model.n_bodies, stepper.carry)
    batch = stepper.new_batch(1)
    driver._keep_state(batch, 0, saved, 0)
    driver._set_existence(model.enters_at, model.leaves_at, saved[4], 0.0)


def compile_driver(world, *, joints: bool = False, timed: bool = False) -> None:
    """Compile (or load) the driver a simulation under `world`'s settings calls (`joints`: its
    scene has joints; `timed`: `--profile`'s timed driver), by one recorded step of the small
    world: numba specialises on argument types only, so it is the run's own. For `isaac run`
    with an empty cache, which compiles the driver before it waits for the recorder's helper
    (`recorder.compile_ahead`) rather than after."""
    from isaac.engine import driver

    small = _SmallWorld(world, joint=joints)
    stepper = driver.Stepper(small.model, small.settings, small.dt, small.work, timed=timed)
    stepper.set_carry(small.cache)
    if WAITING:
        finish()  # the joints' kernels, which the driver's compile links
    stepper.run(small.state, 1, stepper.new_batch(1))


def finish() -> None:
    """Wait for the joints' helper `prepare` started, if any (before the driver's first call:
    its compile links the joints' kernels, which it would otherwise compile itself). A helper
    that fails or takes too long changes nothing: the driver compiles what the cache lacks."""
    while WAITING:
        wait_helper(WAITING.pop())


def wait_helper(proc: subprocess.Popen) -> None:
    """Wait for a compile helper to exit. One that takes longer than HELPER_TIMEOUT_S is killed
    and changes nothing (its caller compiles what the cache lacks); Ctrl-C or a failure while
    waiting kills it (`stop_helper`) and is raised: no helper outlives its process."""
    import subprocess

    try:
        proc.wait(timeout=HELPER_TIMEOUT_S)
    except BaseException as exc:
        stop_helper(proc)
        if not isinstance(exc, subprocess.TimeoutExpired):
            raise
    _close_pipes(proc)


def _stop_waiting() -> None:
    """At exit (a process that never called the driver): no helper outlives it."""
    while WAITING:
        stop_helper(WAITING.pop())


def stop_helper(proc: subprocess.Popen) -> None:
    """Kill a compile helper and reap it (numba writes a cache file whole, a temporary file
    then a rename: a killed helper leaves none half written)."""
    proc.kill()
    proc.wait()
    _close_pipes(proc)


def exited(proc: subprocess.Popen) -> bool:
    """Whether a compile helper has exited (reaped, its pipes closed), without waiting."""
    if proc.poll() is None:
        return False
    _close_pipes(proc)
    return True


def _close_pipes(proc: subprocess.Popen) -> None:
    for pipe in (proc.stdin, proc.stdout):
        if pipe is not None and not pipe.closed:
            try:
                pipe.close()
            except OSError:  # (a write to a helper that exited)
                pass


def _start_helper(world, what: str = "solver", *, talks: bool = False):
    """`python -m isaac.engine.compile_ahead WHAT`, `world` pickled on its standard input; or
    None. talks: a driver's helper, which waits for `release` and says when the solver is
    ready (`_solver_ready`)."""
    import atexit

    proc = start_helper("isaac.engine.compile_ahead", [what], world, talks=talks)
    if proc is not None:
        atexit.register(_stop_waiting)  # (once is enough; registering again is harmless)
    return proc


def start_helper(module: str, args: list[str], job, *, talks: bool = False):
    """A compile helper (subprocess.Popen): ``python -m module args...`` with this checkout on
    its path and `job` pickled on its standard input, its output thrown away (a helper that
    fails only means its caller compiles itself); or None when it cannot start. talks: its
    standard input stays open (`release` writes to it and closes it) and its standard output
    is a pipe to this process (`_solver_ready` reads it)."""
    import subprocess

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE if talks else subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
        )
        proc.stdin.write(pickle.dumps(job, protocol=pickle.HIGHEST_PROTOCOL))
        proc.stdin.flush()
        if not talks:
            proc.stdin.close()
    except OSError:
        return None
    return proc


def _compile_solver(world, joint: bool = False) -> None:
    """The helper's work: one call of the solver stage, on no contact rows (it compiles all the
    same, and numba writes it to the cache); joint: the specialisation with joints, on a box
    hanging by a joint (without: the one a scene without joints calls)."""
    from isaac.engine.step import resolve

    small = _SmallWorld(world, joint=joint)
    resolve(small.model, small.settings, small.state, small.work, small.cache, 0)
    _compile_row_keeping(small)


def _compile_row_keeping(small) -> None:
    """The driver's `keep_rows` (a step's contact rows into the batch), compiled by the solver's
    helper rather than with the driver's other small kernels by its parent, which finished its
    share later (2-core machine, empty cache: the helper exited at 7.4-7.9 s, the parent was done
    at 8.8-9.6 s; `keep_rows` takes about 0.9 s)."""
    from isaac.engine import driver

    stepper = driver.Stepper(small.model, small.settings, small.dt, small.work)
    driver.keep_rows(stepper.new_batch(1), 0, stepper.scratch, 0, 0)


def _compile_joints(world) -> None:
    """The joints' helper's work: the joint kernels the driver calls, on a box hanging by a
    revolute joint (the other stages are this helper's siblings' work)."""
    from isaac.engine.joints import correct_joint_positions
    from isaac.engine.step import _prepare_joints, initial_joint_rows, joint_rows

    small = _SmallWorld(world, joint=True)
    model, state, work = small.model, small.state, small.work
    initial_joint_rows(model, state, work)
    _prepare_joints(model, state, work, small.settings.h, small.cache.joints, True)
    correct_joint_positions(
        model.joints,
        model.joint_waves,
        state.position,
        state.angle,
        state.exists,
        model.inv_mass,
        model.inv_inertia,
        small.settings.position_iterations,
        work.joint_error,
    )
    joint_rows(model, state, work)
    # (keep_joint_impulses, small, is compiled by this process's parent with the other stages)


def _compile_driver_when_told(world, joints: bool) -> None:
    """A driver's helper's work (`prepare`, tiered): the solver (and `keep_rows`), then `READY`
    on standard output; then, once the parent says the other stages are in the cache too (`GO`
    on standard input), the driver. Standard input closed without it (the parent stopped or
    failed): nothing more."""
    _compile_solver(world, joint=joints)
    sys.stdout.buffer.write(READY)
    sys.stdout.buffer.flush()
    if sys.stdin.buffer.read(len(GO)) == GO:
        compile_driver(world, joints=joints)


READY = b"ready"  # a driver's helper to its parent: the solver is in the cache
GO = b"go"  # the parent to a driver's helper: so are the other stages

if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "solver"
    world = pickle.load(sys.stdin.buffer)
    if what in ("driver", "driver-joints"):
        _compile_driver_when_told(world, joints=what == "driver-joints")
    elif what == "joints":
        _compile_joints(world)
    else:
        _compile_solver(world, joint=what == "solver-joints")
