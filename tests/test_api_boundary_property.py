"""Property: whatever record, state array or count a caller hands the public API, the answer
is a result or a TypeError / ValueError (or, for a state that fits but diverges, a
SimulationError), one line, and never a dead interpreter.

The hypothesis cases run in one child process (`hostile`), each printed before it is tried,
so that a segfault or an abort fails `test_hostile_inputs_...` with the case that killed the
child instead of killing pytest. Bounded (MAX_EXAMPLES, derandomized) to run in `make test`.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from api_hostile import in_child, record_of, scene

MAX_EXAMPLES = 40
FIELDS = ("position", "angle", "velocity", "angular_velocity", "exists")
CALLS = ("step", "advance", "run", "batches", "detect", "record")


def test_hostile_inputs_raise_one_line_exceptions_and_never_kill_the_interpreter():
    child = in_child("import test_api_boundary_property as t; t.hostile()")
    tried = [line for line in child.stdout.splitlines() if line.startswith("case ")]
    assert child.returncode == 0, (
        f"the child ended with status {child.returncode} (negative: killed by that signal) "
        f"after {len(tried)} cases; the last tried: {tried[-1:]}\n"
        + "\n".join(child.stderr.splitlines()[-25:])
    )
    assert len(tried) >= MAX_EXAMPLES // 2, child.stdout[-2000:]


def hostile() -> None:
    """The child: MAX_EXAMPLES hostile cases (hypothesis imported here, not in pytest's
    process)."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from isaac.engine.records import CONTACT_FIELDS, JOINT_FIELDS, JointRows
    from isaac.engine.simulation import Simulation
    from isaac.errors import SimulationError, StateError

    configs = st.builds(
        lambda n, joints, dt, enters: dict(
            n=n, joints=min(joints, max(n - 2, 0)), dt=dt, enters=enters
        ),
        st.integers(1, 4),
        st.integers(0, 2),
        st.sampled_from(["0.01", "0.02"]),
        st.sampled_from([None, 0.02]),
    )
    dtypes = st.sampled_from(
        [np.float64, np.float32, np.int64, np.int32, np.uint8, bool, complex, object]
    )
    shapes = st.lists(st.integers(0, 5), min_size=0, max_size=3).map(tuple)
    arrays = st.builds(
        lambda shape, dtype, poison, layout: _array(shape, dtype, poison, layout),
        shapes,
        dtypes,
        st.sampled_from([None, np.nan, np.inf, -np.inf, 1e300, 2**40, -(2**40)]),
        st.sampled_from(["plain", "strided", "read-only", "fortran"]),
    )
    counts = st.one_of(
        st.integers(-(2**70), -1),
        st.integers(0, 6),
        st.integers(2**62 + 1, 2**70),
        st.floats(allow_nan=True),
        st.booleans(),
        st.sampled_from([None, "3", np.int64(3), np.int32(-2), np.float64(2.0), np.bool_(True)]),
    )

    def record_case():
        mutate = st.one_of(
            st.none(),
            st.tuples(st.just("state"), st.sampled_from(FIELDS), arrays),
            st.tuples(st.just("contacts"), st.sampled_from(CONTACT_FIELDS), arrays),
            st.tuples(st.just("joints"), st.sampled_from(JOINT_FIELDS), arrays),
            st.tuples(st.just("joints"), st.just("whole"), st.integers(0, 3)),
            st.tuples(st.just("step"), st.just("step"), counts),
            st.tuples(st.just("time"), st.just("time"), st.floats(allow_nan=True)),
            st.tuples(st.just("object"), st.just("start"), st.sampled_from([42, "r", None, []])),
        )
        return st.tuples(st.just("record"), configs, configs, mutate, st.booleans())

    state_case = st.tuples(
        st.just("state"),
        configs,
        st.sampled_from((*FIELDS, "step", "whole")),
        st.one_of(arrays, counts),
        st.sampled_from(CALLS),
    )
    count_case = st.tuples(
        st.just("count"), configs, st.sampled_from(CALLS[1:4] + ("size", "place")), counts
    )

    def hostile_record(base, mutate):
        if mutate is None:
            return base
        kind, field, value = mutate
        if kind == "state":
            return dataclasses.replace(base, **{field: value})
        if kind == "contacts":
            return dataclasses.replace(
                base, contacts=dataclasses.replace(base.contacts, **{field: value})
            )
        if kind == "joints" and field == "whole":
            return dataclasses.replace(base, joints=JointRows.empty(value))
        if kind == "joints":
            joints = base.joints if base.joints is not None else JointRows.empty(1)
            return dataclasses.replace(base, joints=dataclasses.replace(joints, **{field: value}))
        if kind in ("step", "time"):
            return dataclasses.replace(base, **{kind: value})
        return value  # not a record at all

    def then_steps(sim):
        """A simulation that took an input goes on, or stops with SimulationError."""
        try:
            sim.step()
            sim.advance(2)
            list(sim.run(2))
        except SimulationError:
            pass

    def call(sim, name, value=None):
        if name == "step":
            sim.step()
        elif name == "advance":
            sim.advance(2 if value is None else value)
        elif name == "run":
            list(sim.run(2 if value is None else value))
        elif name == "batches":
            list(sim.batches(2 if value is None else value))
        elif name == "size":
            list(sim.batches(2, size=value))
        elif name == "place":
            next(sim.batches(2)).record(value)
        elif name == "detect":
            sim.detect()
        else:
            sim.record()

    @settings(max_examples=MAX_EXAMPLES, deadline=None, database=None, derandomize=True)
    @given(st.one_of(record_case(), state_case, count_case))
    def case(c):
        print("case", _brief(c), flush=True)
        kind, config = c[0], c[1]
        sim = Simulation(scene(**config))
        try:
            if kind == "record":
                _, _, other, mutate, at_start = c
                record = hostile_record(record_of(**other), mutate)
                if at_start:
                    sim = Simulation(sim.scene, start=record)
                else:
                    sim.resume(record)
            elif kind == "state":
                _, _, field, value, name = c
                sim.step()
                if field == "whole":
                    sim.state = value
                else:
                    setattr(sim.state, field, value)
                call(sim, name)
            else:
                _, _, name, value = c
                before = sim.step_index
                call(sim, name, value)
                assert type(sim.step_index) is int and sim.step_index >= before
                return
        except (TypeError, ValueError, SimulationError) as exc:
            assert "\n" not in str(exc), str(exc)
            # the guards' own errors, not one raised deeper down (numpy's "could not broadcast")
            ours = isinstance(exc, (StateError, SimulationError)) or "must be" in str(exc)
            assert ours or "past the batch's last" in str(exc), repr(exc)
            return
        then_steps(sim)

    case()
    print("done", flush=True)


def _array(shape, dtype, poison, layout):
    a = np.zeros(shape, dtype=dtype)
    if poison is not None and a.size:
        try:
            a.flat[0] = poison
        except (OverflowError, ValueError, TypeError):
            pass
    if layout == "strided" and a.ndim:
        a = np.repeat(a, 2, axis=0)[::2]
    elif layout == "read-only":
        a.flags.writeable = False
    elif layout == "fortran":
        a = np.asfortranarray(a)
    return a


def _brief(case) -> str:
    """A case in one line: arrays as their shape, dtype and first value."""

    def one(x):
        if isinstance(x, np.ndarray):
            first = x.flat[0] if x.size else "-"
            return f"array{x.shape}:{x.dtype}:{first}"
        if isinstance(x, tuple):
            return "(" + ", ".join(one(y) for y in x) + ")"
        return repr(x)

    return one(case)
