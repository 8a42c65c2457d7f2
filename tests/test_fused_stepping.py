"""The compiled driver (isaac.engine.driver) gives the same bits as stepping stage by stage:
`step()` x n, `run(n)`, `advance(n)` then `record()`, and `batches(n)` of any size agree on
every state and every contact row, whether or not a buffer had to grow on the way, and a
diverging run stops at the same step, naming the same body."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from physics_helpers import diverging

from isaac.engine.records import CONTACT_FIELDS, StepBatch, StepRecord
from isaac.engine.simulation import Simulation
from isaac.errors import SimulationError
from isaac.scene import PRESETS, Scene, WorldSettings, generators, load_scene

STEPS = 40
SCENE_DIR = Path(__file__).resolve().parents[1] / "scenes"


def _pile(preset: str, **world) -> Scene:
    settings = WorldSettings(
        **{
            **PRESETS[preset],
            "fidelity": preset,
            "dt": 1 / 60,
            "steps": STEPS,
            "friction": True,
            **world,
        }
    )
    return Scene("pile", settings, tuple(generators.pile(count=40, seed=5, width=4.0)))


SCENES = {
    "pile-balanced": lambda: _pile("balanced"),
    "pile-seed": lambda: _pile("seed"),
    "pile-fast": lambda: _pile("fast"),
    "pile-accurate": lambda: _pile("accurate"),  # 4 sub-steps: rows of every sub-step kept
    "spawn": lambda: load_scene(SCENE_DIR / "spawn.yaml"),  # bodies entering and leaving
    "head-on": lambda: load_scene(SCENE_DIR / "head_on.yaml"),
}


def _same_record(x, y) -> None:
    assert x.step == y.step and x.time == y.time
    for f in ("position", "angle", "velocity", "angular_velocity", "exists"):
        a, b = getattr(x, f), getattr(y, f)
        assert a.dtype == b.dtype and np.array_equal(a, b), f
        assert a.tobytes() == b.tobytes(), f  # -0.0 and NaN payloads too
    assert len(x.contacts) == len(y.contacts)
    for f in CONTACT_FIELDS:
        a, b = getattr(x.contacts, f), getattr(y.contacts, f)
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), f


def _stepped(scene: Scene, n: int):
    sim = Simulation(scene, staged=True)
    return [sim.step() for _ in range(n)]


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_path_gives_the_staged_steps_bits(name):
    scene = SCENES[name]()
    n = min(STEPS, 60)
    reference = _stepped(scene, n)
    assert sum(len(r.contacts) for r in reference) > 0 or name == "head-on"

    _all_same(reference, list(Simulation(scene).run(n)))
    sim = Simulation(scene)
    _all_same(reference, [sim.step() for _ in range(n)])
    assert sim._step_driver  # one driver call a step (numba has the driver by now)
    for size in (1, 7, 64):
        sim = Simulation(scene)
        got = [b.record(s) for b in sim.batches(n, size=size) for s in range(len(b))]
        _all_same(reference, got)
    sim = Simulation(scene)
    sim.advance(n)
    _same_record(reference[-1], sim.record())
    # and the stepping goes on from there with the same bits
    _same_record(_stepped(scene, n + 1)[-1], sim.step())


def _all_same(reference, got) -> None:
    assert len(got) == len(reference)
    for x, y in zip(reference, got):
        _same_record(x, y)


def test_mixing_step_run_and_advance_keeps_the_bits():
    scene = _pile("balanced")
    reference = _stepped(scene, 30)
    sim = Simulation(scene)
    got = [sim.step() for _ in range(5)]
    got += list(sim.run(10))
    sim.advance(5)
    got += [None] * 5
    got += [sim.step() for _ in range(10)]
    for x, y in zip(reference, got):
        if y is not None:
            _same_record(x, y)


def test_a_batch_that_outgrows_its_buffers_gives_the_bits_of_one_sized_generously():
    scene = _pile("accurate")
    generous = Simulation(scene)
    generous._work.grow(4096)
    generous._stepper._rows_per_step = 100_000
    big = [b.record(s) for b in generous.batches(STEPS, size=STEPS) for s in range(len(b))]

    tight = Simulation(scene)
    tight._stepper._rows_per_step = 1  # room for 40 rows: a 4-sub-step pile makes ~100 a step
    batches = list(tight.batches(STEPS, size=STEPS))
    assert batches[0]._rows[1].shape[0] > 40 * 2  # its rows grew (doubling) mid-batch
    small = [b.record(s) for b in batches for s in range(len(b))]
    _all_same(big, small)


def test_pair_buffers_grow_mid_batch_without_changing_a_bit():
    scene = _pile("balanced")
    reference = _stepped(scene, STEPS)
    sim = Simulation(scene)
    sim._work._allocate(1)  # one candidate pair of room: the first step must grow it
    sim._stepper._fit()
    got = list(sim.run(STEPS))
    assert sim._work.pair_a.shape[0] > 1
    _all_same(reference, got)


def test_a_solver_scratch_that_grows_mid_run_gives_the_bits_of_one_sized_generously():
    # the sequential solver's scratch: too small, the solver asks for more and changes nothing,
    # the driver undoes the step and the caller grows it and calls again (the staged path
    # grows it and calls the solver again)
    scene = _pile("balanced")
    generous = Simulation(scene)
    generous._work.solver_table = np.zeros(1_000_000)
    big = list(generous.run(STEPS))

    tight = Simulation(scene)
    tight._work.solver_table = np.zeros(1)
    got, sizes = [], []
    for _ in range(STEPS // 5):
        got += list(tight.run(5))
        sizes.append(tight._work.solver_table.shape[0])
    assert len(set(sizes)) > 2  # it grew at several points of the run, not once at the start
    _all_same(big, got)

    staged = Simulation(scene, staged=True)
    staged._work.solver_table = np.zeros(1)
    _all_same(big, [staged.step() for _ in range(STEPS)])


def test_a_diverging_run_stops_at_the_same_step_naming_the_same_body():
    scene = diverging()
    staged = Simulation(scene, staged=True)
    kept = []
    with pytest.raises(SimulationError) as want:
        for _ in range(50):
            kept.append(staged.step())
    for how in ("step", "run", "advance", "batches"):
        sim = Simulation(scene)
        got = []
        with pytest.raises(SimulationError) as err:
            if how == "step":
                for _ in range(50):
                    got.append(sim.step())
            elif how == "run":
                got.extend(sim.run(50))
            elif how == "advance":
                sim.advance(50)
            else:
                for batch in sim.batches(50, size=8):
                    got.extend(batch.record(s) for s in range(len(batch)))
        assert (err.value.step, err.value.body) == (want.value.step, want.value.body), how
        assert str(err.value) == str(want.value)
        if how != "advance":
            _all_same(kept, got)
        # the state is the one before the failing step, as after step()
        for f in ("position", "velocity", "angle", "angular_velocity"):
            assert np.array_equal(getattr(sim.state, f), getattr(staged.state, f))
        assert sim.step_index == staged.step_index


def test_batch_arrays_are_read_only_views_of_one_batch():
    sim = Simulation(_pile("balanced"))
    batch = next(sim.batches(10, size=10))
    assert len(batch) == 10 and batch.position.shape == (10, sim.n_bodies, 2)
    assert not batch.position.flags.writeable
    record = batch.record(3)
    assert record.step == batch.first + 3 and not record.position.flags.writeable
    c = batch.contacts_of(3)
    assert len(c) == batch.offsets[4] - batch.offsets[3]
    with pytest.raises(ValueError):
        record.contacts.impulse[...] = 0.0


def test_advance_computes_the_last_steps_contacts_only_when_asked_and_exactly():
    # advance records nothing; record() afterwards computes the last step again from its start
    scene = _pile("balanced")
    reference = _stepped(scene, 40)
    sim = Simulation(scene)
    sim.advance(25)
    assert sim._contacts is None  # not computed yet
    _same_record(reference[24], sim.record())
    assert len(sim.record().contacts) > 0
    sim.advance(3)
    sim.advance(2)  # the pending contacts of the first call are never needed
    _same_record(reference[29], sim.record())
    after = [sim.step() for _ in range(10)]
    for x, y in zip(reference[30:], after):
        _same_record(x, y)


def test_a_batch_record_pickles_as_a_plain_step_record_with_the_same_bits():
    import pickle

    sim = Simulation(_pile("balanced"))
    record = next(sim.batches(8, size=8)).record(7)
    copy = pickle.loads(pickle.dumps(record))
    assert type(copy) is StepRecord and repr(copy).startswith("StepRecord(step=8")
    _same_record(record, copy)


def test_a_record_after_advance_goes_through_the_compiled_finiteness_check():
    from isaac.engine.diagnostics import all_finite

    sim = Simulation(_pile("balanced"))
    sim.advance(25)
    record = sim.record()
    assert len(record.contacts) > 0 and all_finite(record)


def test_a_record_after_batches_goes_through_the_compiled_finiteness_check():
    from isaac.engine.diagnostics import all_finite

    sim = Simulation(_pile("balanced"))
    for _ in sim.batches(25, size=7):
        pass
    record = sim.record()
    assert len(record.contacts) > 0 and all_finite(record)
    assert all(getattr(record.contacts, f).flags.writeable for f in CONTACT_FIELDS)


def _copied(record) -> StepRecord:
    """A record with copies of its arrays (what it held when copied)."""
    fields = {f: getattr(record, f) for f in StepRecord.__dataclass_fields__}
    for f in ("position", "angle", "velocity", "angular_velocity", "exists"):
        fields[f] = fields[f].copy()
    contacts = record.contacts
    fields["contacts"] = type(contacts)(*(getattr(contacts, f).copy() for f in CONTACT_FIELDS))
    return StepRecord(**fields)


def test_batches_and_records_still_held_are_never_written_again():
    """The driver reuses the arrays of batches nothing references any more
    (`Stepper.reused_batch`): every batch and record a caller keeps holds its own step."""
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    held_batches, held_records, as_made = [], [], []
    for i, batch in enumerate(sim.batches(STEPS, size=3)):
        if i % 3 == 0:
            held_batches.append(batch)  # every third batch kept whole
        elif i % 3 == 1:
            held_records.append(batch.record(batch.steps - 1))  # of another, one record (a view)
        as_made.extend(_copied(batch.record(s)) for s in range(batch.steps))
    by_step = {r.step: r for r in as_made}
    assert len(by_step) == STEPS
    for batch in held_batches:
        for s in range(batch.steps):
            _same_record(batch.record(s), by_step[batch.first + s])
    for record in held_records:
        _same_record(record, by_step[record.step])
    expected = _stepped(scene, STEPS)
    for x, y in zip([by_step[s + 1] for s in range(STEPS)], expected):
        _same_record(x, y)


def test_the_arrays_of_a_batch_nothing_references_are_reused():
    sim = Simulation(SCENES["pile-balanced"]())
    addresses = set()
    for batch in sim.batches(STEPS, size=4):
        addresses.add(batch.position.__array_interface__["data"][0])
        del batch  # (the loop's name: the caller keeps nothing)
    # 10 batches in at most SPARE_BATCHES + 1 sets of arrays (the simulation keeps its last
    # record, and the generator the batch it is yielding)
    assert len(addresses) <= 4


def test_a_smaller_batch_reuses_a_larger_ones_arrays_and_keeps_its_bits():
    """`run(n)` after `run(m)` (a bench's warm-up, then its timed block) ends in batches of
    other sizes: a spare batch with room for more steps serves a smaller one (fresh arrays
    cost page faults: pyramid-10's `run` took 76-95 us a step against 65-66 reusing them)."""
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    larger = set()
    for batch in sim.batches(24, size=8):
        larger.add(batch.position.__array_interface__["data"][0])
        del batch
    made, smaller = [], set()
    for batch in sim.batches(STEPS - 24, size=5):
        smaller.add(batch.position.__array_interface__["data"][0])
        assert batch.position.shape[0] == batch.steps <= 5
        made.extend(_copied(batch.record(s)) for s in range(batch.steps))
        del batch
    assert smaller & larger  # the 8-step arrays were taken again
    expected = _stepped(scene, STEPS)[24:]
    assert [r.step for r in made] == [r.step for r in expected]
    for x, y in zip(made, expected):
        _same_record(x, y)


def test_a_short_batchs_arrays_serve_the_next_runs_full_batch_and_keep_its_bits():
    """A batch of 6 steps is made with room for 8 (the power of two at or above), so that
    the next run's batches of 8 take its arrays rather than fresh ones (a bench's warm-up
    `run(60)`, then batches of 64). Its last record is the simulation's last while the next
    run's first batch is made: the second takes it."""
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    short = set()
    for batch in sim.batches(6, size=8):
        assert batch.steps == batch.position.shape[0] == 6
        short.add(batch.position.__array_interface__["data"][0])
        del batch
    made, full = [], []
    for batch in sim.batches(STEPS - 6, size=8):
        full.append(batch.position.__array_interface__["data"][0])
        made.extend(_copied(batch.record(s)) for s in range(batch.steps))
        del batch
    assert full[0] not in short and full[1] in short
    expected = _stepped(scene, STEPS)[6:]
    assert [r.step for r in made] == [r.step for r in expected]
    for x, y in zip(made, expected):
        _same_record(x, y)


def test_records_of_step_still_held_and_arrays_taken_from_them_are_never_written_again():
    """`step()` records into one-step slots it uses again once nothing holds them
    (`isaac.engine.step_slots`): a record kept, or an array taken from a record that was
    dropped, keeps its own step."""
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    kept, arrays, as_made = [], [], []
    for i in range(STEPS):
        record = sim.step()
        as_made.append(_copied(record))
        if i % 3 == 0:
            kept.append(record)
        elif i % 3 == 1:
            arrays.append((record.step, record.velocity, record.contacts.impulse))
        del record
    by_step = {r.step: r for r in as_made}
    for record in kept:
        _same_record(record, by_step[record.step])
    for step, velocity, impulse in arrays:
        assert velocity.tobytes() == by_step[step].velocity.tobytes()
        assert impulse.tobytes() == by_step[step].contacts.impulse.tobytes()
    _all_same(_stepped(scene, STEPS), as_made)


def test_step_writes_into_the_same_few_slots_when_no_record_is_held():
    sim = Simulation(SCENES["pile-balanced"]())
    blocks = set()
    for _ in range(STEPS):
        blocks.add(sim.step().position.base.__array_interface__["data"][0])
    # the simulation keeps its last record: the slots take turns (at most SPARE_BATCHES)
    assert len(blocks) <= 3
    assert not sim.step().position.flags.writeable


def _blocks(records) -> dict[int, int]:
    """The slots the records hold: {id of the slot's batch: its steps}."""
    return {id(r._batch): r._batch.steps for r in records if hasattr(r, "_batch")}


def test_step_records_a_caller_keeps_share_slots_and_keep_their_bits():
    """A caller that keeps every record of `step()` holds every slot: the next step goes in
    the place after the last record (a slot a step made them 12x slower on head-on)."""
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    kept = [sim.step() for _ in range(2 * STEPS)]
    assert len(_blocks(kept)) <= 12  # slots of 1, 2, 4, ... steps, not one a step
    _all_same(_stepped(scene, 2 * STEPS), kept)


@pytest.mark.parametrize("every", [2, 3, 10])
def test_a_caller_keeping_some_step_records_pins_about_what_it_keeps(every):
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    kept, as_made = [], []
    for i in range(2 * STEPS):
        record = sim.step()
        as_made.append(_copied(record))
        if i % every == 0:
            kept.append(record)
        del record
    assert sum(_blocks(kept).values()) <= 2 * len(kept)
    by_step = {r.step: r for r in as_made}
    for record in kept:
        _same_record(record, by_step[record.step])


def test_batches_held_are_not_filled_by_the_steps_after_them():
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    records = [sim.step() for _ in range(6)]  # slots of 1, 2 and 4 steps, the last 3/4 full
    del records  # free again: the batches take them
    batches = list(sim.batches(8, size=4))  # two batches held whole, each filling its slot
    as_made = [_copied(b.record(s)) for b in batches for s in range(b.steps)]
    records = [sim.step() for _ in range(STEPS)]  # every slot held: steps fill new ones
    _all_same(as_made, [b.record(s) for b in batches for s in range(b.steps)])
    _all_same(_stepped(scene, 14 + STEPS)[14:], records)


def test_batches_a_caller_keeps_share_slots_and_keep_their_bits():
    """`list(sim.run(n))` holds every batch: the next goes in the places after the last one
    (a slot a batch made head-on's `run` 2.3x slower), each a batch of its own."""
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    kept = list(sim.batches(2 * STEPS, size=4))
    blocks = {b.position.base.__array_interface__["data"][0] for b in kept}
    assert len(blocks) < len(kept) // 2  # 20 batches in slots of 4, 8, 16, ... steps
    expected = _stepped(scene, 2 * STEPS)
    _all_same(expected, [b.record(s) for b in kept for s in range(b.steps)])
    for batch in kept:  # each batch's rows are its own steps', from its own offset 0
        assert batch.offsets[0] == 0
        rows = batch.all_contacts()
        want = [expected[batch.first - 1 + s].contacts for s in range(batch.steps)]
        assert len(rows) == sum(len(c) for c in want)
        for f in CONTACT_FIELDS:
            joined = np.concatenate([getattr(c, f) for c in want])
            assert getattr(rows, f).tobytes() == joined.tobytes(), f


@pytest.mark.parametrize("every", [2, 3, 10])
def test_a_caller_keeping_some_batches_pins_about_what_it_keeps(every):
    sim = Simulation(SCENES["pile-balanced"]())
    kept, as_made = [], []
    for i, batch in enumerate(sim.batches(4 * STEPS, size=2)):
        as_made.extend(_copied(batch.record(s)) for s in range(batch.steps))
        if i % every == 0:
            kept.append(batch)
        del batch
    slots = {id(b._slot_batch): b._slot_batch.steps for b in kept if hasattr(b, "_slot_batch")}
    slots.update({id(b): b.steps for b in kept if not hasattr(b, "_slot_batch")})
    assert sum(slots.values()) <= 2 * 2 * len(kept) + 16
    by_step = {r.step: r for r in as_made}
    for batch in kept:
        for s in range(batch.steps):
            _same_record(batch.record(s), by_step[batch.first + s])


@pytest.fixture
def grown_rows(monkeypatch) -> list[int]:
    """The rows asked for each time a batch grew (`isaac.engine.driver._grown_rows`)."""
    from isaac.engine import driver

    original, grown = driver._grown_rows, []

    def counted(batch, need):
        grown.append(need)
        return original(batch, need)

    monkeypatch.setattr(driver, "_grown_rows", counted)
    return grown


def test_a_step_whose_rows_outgrow_its_slot_gives_the_staged_steps_bits(grown_rows):
    grown = grown_rows
    scene = _pile("accurate")  # 4 sub-steps: some 100 rows a step
    sim = Simulation(scene)
    sim._stepper._rows_per_step = 1  # the first slot has room for 16 rows
    got = [sim.step() for _ in range(STEPS)]
    assert grown and grown[0] > 16  # a step's rows did not fit: its batch grew
    _all_same(_stepped(scene, STEPS), got)


def test_a_step_that_outgrows_its_slot_in_one_call_is_taken_again_with_the_same_bits(
    grown_rows,
):
    grown = grown_rows
    scene = _pile("accurate")  # 4 sub-steps: some 100 rows a step
    sim = Simulation(scene)
    got = [sim.step() for _ in range(STEPS // 2)]
    stepper = sim._stepper
    assert stepper.kit is not None  # the next step() is one driver call
    stepper._slots.clear()  # the next slot is made with room for 16 rows
    stepper._held = None
    stepper._rows_per_step = 1
    before = len(grown)
    got += [sim.step() for _ in range(STEPS - STEPS // 2)]
    assert grown[before:] and grown[before] > 16  # that call did not fit: undone, taken again
    _all_same(_stepped(scene, STEPS), got)


def test_state_arrays_replaced_between_steps_are_the_ones_the_next_step_advances():
    scene = _pile("balanced")
    sim, staged = Simulation(scene), Simulation(scene, staged=True)
    for _ in range(5):
        sim.step(), staged.step()
    for s in (sim, staged):  # a user's assignment of new arrays (a kick upwards)
        s.state.velocity = s.state.velocity + np.array([0.0, 2.0])
        s.state.position = s.state.position.copy()
    moved = sim.state.position
    got, want = [sim.step() for _ in range(5)], [staged.step() for _ in range(5)]
    assert sim.state.position is moved and np.array_equal(moved, want[-1].position)
    _all_same(want, got)


def test_arrays_a_batch_hands_out_are_never_written_again_after_the_batch_is_dropped():
    """A batch's slot is used again once nothing holds it: not while a caller keeps only an
    array or the row tuple it handed out as it is (`position`, `row_arrays`)."""
    scene = SCENES["pile-balanced"]()
    sim = Simulation(scene)
    kept, as_made = [], []
    for i, batch in enumerate(sim.batches(STEPS, size=4)):
        as_made.extend(_copied(batch.record(s)) for s in range(batch.steps))
        if i % 3 == 0:
            kept.append((batch.first, batch.position, None))
        elif i % 3 == 1:
            kept.append((batch.first, None, (batch.offsets.copy(), batch.row_arrays)))
        del batch
    by_step = {r.step: r for r in as_made}
    for first, position, rows in kept:
        for s in range(4):
            made = by_step[first + s]
            if position is not None:
                assert position[s].tobytes() == made.position.tobytes()
            else:
                offsets, arrays = rows
                lo, hi = offsets[s], offsets[s + 1]
                assert arrays[7][lo:hi].tobytes() == made.contacts.depth.tobytes()
    _all_same(_stepped(scene, STEPS), as_made)


def test_replace_on_a_record_of_a_batch_gives_a_plain_step_record():
    import dataclasses

    sim = Simulation(_pile("balanced"))
    record = sim.step()
    still = np.zeros_like(record.velocity)
    changed = dataclasses.replace(record, velocity=still)
    assert type(changed) is StepRecord and changed.step == record.step
    assert changed.velocity is still and changed.position is record.position


def test_detect_between_driven_steps_finds_the_staged_contacts_and_changes_no_bit():
    """`detect()` reads the last step's contacts where the driver keeps them (hysteresis):
    the contacts a staged simulation finds at the same state, and the steps after it keep
    their bits."""
    scene = SCENES["pile-balanced"]()
    driven, staged = Simulation(scene), Simulation(scene, staged=True)
    got, expected, rows = [], [], 0
    for _ in range(STEPS):
        got.append(driven.step())
        expected.append(staged.step())
        assert driven._step_driver  # (the driver's carry, not a copy taken out of it)
        found, want = driven.detect(), staged.detect()
        assert len(want) == len(found)
        for f in CONTACT_FIELDS:
            assert getattr(found, f).tobytes() == getattr(want, f).tobytes(), f
        rows += len(found)
    assert rows > 0
    _all_same(expected, got)


def test_whatever_a_caller_keeps_of_mixed_calls_keeps_its_bits():
    """step(), run(), batches() and advance() in a fixed pseudo-random mix, keeping some of the
    records, batches and arrays they hand out (and dropping the rest): everything kept still
    holds what it held when handed out, which is the staged path's step."""
    scene = SCENES["pile-balanced"]()
    expected = {r.step: r for r in _stepped(scene, 4 * STEPS)}
    sim = Simulation(scene)
    rng = np.random.default_rng(12)
    kept, copies = [], []  # (step, what) and (step, its copy when handed out)

    def hand_out(step, thing, copy):
        if rng.random() < 0.4:
            kept.append((step, thing))
            copies.append((step, copy))

    while sim.state.step < 4 * STEPS - 12:
        what = rng.integers(4)
        if what == 0:
            record = sim.step()
            hand_out(record.step, record, _copied(record))
        elif what == 1:
            for record in sim.run(int(rng.integers(1, 6)), batch=int(rng.integers(1, 4))):
                hand_out(record.step, record, _copied(record))
        elif what == 2:
            for batch in sim.batches(int(rng.integers(1, 9)), size=int(rng.integers(1, 5))):
                if rng.random() < 0.3:  # an array taken from a record of it, the batch dropped
                    record = batch.record(batch.steps - 1)
                    hand_out(record.step, record.velocity, record.velocity.copy())
                elif rng.random() < 0.3:  # the batch itself
                    hand_out(
                        batch.first, batch, [_copied(batch.record(s)) for s in range(batch.steps)]
                    )
                else:
                    for s in range(batch.steps):
                        record = batch.record(s)
                        hand_out(record.step, record, _copied(record))
        else:
            sim.advance(int(rng.integers(1, 4)))
    assert len(kept) > 30
    for (step, thing), (_, copy) in zip(kept, copies):
        if isinstance(thing, StepBatch):
            _all_same(copy, [thing.record(s) for s in range(thing.steps)])
            _all_same([expected[step + s] for s in range(thing.steps)], copy)
        elif isinstance(thing, np.ndarray):
            assert thing.tobytes() == copy.tobytes() == expected[step].velocity.tobytes()
        else:
            _same_record(thing, copy)
            _same_record(thing, expected[step])
