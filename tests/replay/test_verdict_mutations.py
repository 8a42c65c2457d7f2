"""`identical` is said only of a log whose every claimed step was present, intact and compared.

A small log (3 bodies, steps 0..50, 7 chunks) is recorded in this process and damaged ~170
ways: chunks removed or zeroed, bytes flipped inside chunk data (CRC left stale), cuts at many
offsets, messages or whole steps dropped, swapped or repeated (rewritten with the mcap Writer,
so every CRC and the summary agree with the edit), the summary's statistics and the recorder's
``isaac.end`` edited. The replay verdict must be ``identical`` (exit 0) for the untouched log
and for edits that change no payload byte only; every other one exits 1 or 2 and names the
first damaged or missing step or byte. The findings of the issue this reproduces (logs that
replayed ``identical``, exit 0): a chunk removed from the middle, the last chunk zeroed, one
step's /bodies dropped, every /stats dropped, a flipped byte in a chunk with a stale CRC, a
.partial killed before its first chunk.
"""

from __future__ import annotations

import re
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

from isaac.app.cli import main
from isaac.errors import LogError, SceneError
from recorder import schema as S
from recorder.reader import LogReader, recover
from replay.compare import diff_logs, replay_log
from replay.report import format_text

sys.path.insert(0, str(Path(__file__).parent))
from mcap_surgery import (  # noqa: E402
    STEPS,
    TINY,
    abandoned_log,
    crafted,
    layout,
    rewrite,
    small_log,
    summary_crc,
)

NAMED = re.compile(r"\b(step|byte)s? \d")


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    return small_log(tmp_path_factory.mktemp("clean") / "tiny.mcap")


def verdict(path: Path, **kw) -> tuple[int, str]:
    """(exit status, text) of `isaac replay` on ``path``, run in this process."""
    try:
        report = replay_log(str(path), **kw)
    except (LogError, SceneError) as exc:
        return 2, str(exc)
    return report.exit_status, format_text(report)


def isaac(capsys, *argv) -> tuple[int, str, str]:
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def _byte_mutations(clean: Path) -> list[tuple[str, bytes, bool]]:
    """(name, file bytes, changes a payload byte) of every byte-level mutation."""
    data = clean.read_bytes()
    records, chunks = layout(clean)
    out = []
    # a whole chunk removed (its record and the message indexes after it), summary left stale
    for k in range(1, len(chunks) - 1):
        c = chunks[k]
        after = next(i for i, r in enumerate(records) if r.start == c.record.start) + 1
        end = c.record.end
        while records[after].opcode == 0x07:  # its message index records
            end = records[after].end
            after += 1
        out.append((f"chunk {k} removed", data[: c.record.start] + data[end:], True))
    # the last chunk zeroed: its data only, and the whole record
    last = chunks[-1]
    for name, lo in (("data", last.data_start), ("record", last.record.start)):
        b = bytearray(data)
        b[lo : last.record.end] = bytes(last.record.end - lo)
        out.append((f"last chunk's {name} zeroed", bytes(b), True))
    # one flipped byte inside a chunk's data, CRC left stale: 60 places over every chunk
    rng = np.random.default_rng(20261201)
    for _ in range(60):
        c = chunks[int(rng.integers(len(chunks)))]
        at = int(rng.integers(c.data_start, c.data_end))
        b = bytearray(data)
        b[at] ^= 1 << int(rng.integers(8))
        out.append((f"byte {at} flipped (chunk of steps {c.first_step}..)", bytes(b), True))
    # cut at 50 places, from inside the header to one byte short of the end
    for cut in np.unique(np.linspace(9, len(data) - 1, 50).astype(int)):
        out.append((f"cut at byte {cut}", data[:cut], True))
    # the summary's statistics edited (a message count), with and without the CRC agreeing
    stats = next(r for r in records if r.opcode == 0x0B)
    # Statistics: message_count u64, schema u16, channel u32, attachment u32, metadata u32,
    # chunk u32, start u64, end u64, then the per-channel map (u32 length, (u16, u64) pairs)
    first_count = stats.start + 9 + 42 + 4 + 2
    for fix_crc in (False, True):
        b = bytearray(data)
        struct.pack_into("<Q", b, first_count, struct.unpack_from("<Q", b, first_count)[0] + 1)
        if fix_crc:
            summary_crc(b)
        out.append((f"summary channel count edited (crc fixed: {fix_crc})", bytes(b), True))
        b = bytearray(data)
        chunk_count = stats.start + 9 + 8 + 2 + 4 + 4 + 4
        struct.pack_into("<I", b, chunk_count, 6)
        if fix_crc:
            summary_crc(b)
        out.append((f"summary chunk count edited (crc fixed: {fix_crc})", bytes(b), True))
    # flips outside any chunk (message indexes, summary, footer): no payload byte changes
    outside = [
        r for r in records if r.opcode in (0x07, 0x08, 0x0B, 0x0D, 0x0E, 0x02, 0x0F, 0x03, 0x04)
    ]
    for _ in range(15):
        r = outside[int(rng.integers(len(outside)))]
        at = int(rng.integers(r.start, r.end))
        b = bytearray(data)
        b[at] ^= 1 << int(rng.integers(8))
        out.append((f"byte {at} flipped (record 0x{r.opcode:02x})", bytes(b), False))
    return out


def _writer_mutations(clean: Path, tmp: Path) -> list[tuple[str, Path, bool]]:
    """(name, path, changes a payload) of the mutations rewritten with the mcap Writer."""

    def drop(pred):
        return lambda ms: [m for m in ms if not pred(m)]

    def swap_steps(a, b):
        def edit(ms):
            sa = [m for m in ms if m[1] == a]
            sb = [m for m in ms if m[1] == b]
            i = ms.index(sa[0])
            rest = [m for m in ms if m[1] not in (a, b)]
            return rest[:i] + sb + sa + rest[i:]

        return edit

    def repeat_step(k):
        def edit(ms):
            i = max(j for j, m in enumerate(ms) if m[1] == k) + 1
            return ms[:i] + [m for m in ms if m[1] == k] + ms[i:]

        return edit

    def repeat_message(topic, k):
        def edit(ms):
            i = next(j for j, m in enumerate(ms) if m[:2] == (topic, k))
            return ms[: i + 1] + [ms[i]] + ms[i + 1 :]

        return edit

    def swap_payloads(topic, a, b):
        def edit(ms):
            ia = next(j for j, m in enumerate(ms) if m[:2] == (topic, a))
            ib = next(j for j, m in enumerate(ms) if m[:2] == (topic, b))
            ms = list(ms)
            ma, mb = ms[ia], ms[ib]
            ms[ia], ms[ib] = (*ma[:3], mb[3]), (*mb[:3], ma[3])
            return ms

        return edit

    cases = [
        ("rewritten unchanged", None, None, False),
        ("step 25's /bodies dropped", drop(lambda m: m[:2] == ("/bodies", 25)), None, True),
        ("step 0's /contacts dropped", drop(lambda m: m[:2] == ("/contacts", 0)), None, True),
        ("the last step's /stats dropped", drop(lambda m: m[:2] == ("/stats", STEPS)), None, True),
        ("every /stats dropped", drop(lambda m: m[0] == "/stats"), None, True),
        ("step 0's /world dropped", drop(lambda m: m[:2] == ("/world", 0)), None, True),
        ("step 30 dropped", drop(lambda m: m[1] == 30), None, True),
        ("steps 12..17 dropped", drop(lambda m: 12 <= m[1] <= 17), None, True),
        ("the last step dropped", drop(lambda m: m[1] == STEPS), None, True),
        ("steps 0..4 dropped", drop(lambda m: m[1] <= 4), None, True),
        ("steps 20 and 21 swapped", swap_steps(20, 21), None, True),
        ("step 33 repeated", repeat_step(33), None, True),
        ("step 7's /stats repeated", repeat_message("/stats", 7), None, True),
        ("/bodies payloads of 40 and 41 swapped", swap_payloads("/bodies", 40, 41), None, True),
        ("isaac.end dropped", None, lambda e: None, True),
        ("isaac.end claims one step more", None, lambda e: {**e, "steps_written": "52"}, True),
        ("isaac.end claims a later last step", None, lambda e: {**e, "last_step": "51"}, True),
        ("isaac.end malformed", None, lambda e: {**e, "steps_written": "5x"}, True),
    ]
    out = []
    for k, (name, edit, end, changes) in enumerate(cases):
        out.append((name, rewrite(clean, tmp / f"w{k}.mcap", edit, end=end), changes))
    return out


def test_only_an_intact_log_replays_identical(clean, tmp_path):
    assert verdict(clean)[0] == 0 and verdict(clean)[1].startswith("identical: replayed 51 steps")
    cases = [(name, data, changes) for name, data, changes in _byte_mutations(clean)]
    paths = []
    for k, (name, data, changes) in enumerate(cases):
        path = tmp_path / f"b{k}.mcap"
        path.write_bytes(data)
        paths.append((name, path, changes))
    paths += _writer_mutations(clean, tmp_path)
    assert len(paths) >= 150
    wrong = []
    for name, path, changes in paths:
        status, text = verdict(path)
        if status == 0 and changes:
            wrong.append(f"{name}: {text.splitlines()[0]}")
        elif status != 0:
            if status not in (1, 2) or not NAMED.search(text):
                wrong.append(f"{name}: exit {status} without naming a step or byte: {text}")
            if text.startswith("identical"):
                wrong.append(f"{name}: says identical with exit {status}")
    assert not wrong, "\n".join(wrong)


def test_the_untouched_rewrite_is_identical_and_the_counted_edits_are_not(clean, tmp_path):
    # the two ends of the scale, named: a byte-identical payload set replays identical; a
    # summary that counts one message more than the file holds does not
    same = rewrite(clean, tmp_path / "same.mcap")
    assert verdict(same)[0] == 0
    records, _ = layout(clean)
    stats = next(r for r in records if r.opcode == 0x0B)
    b = bytearray(clean.read_bytes())
    at = stats.start + 9 + 42 + 4 + 2
    struct.pack_into("<Q", b, at, struct.unpack_from("<Q", b, at)[0] + 1)
    summary_crc(b)
    edited = tmp_path / "edited.mcap"
    edited.write_bytes(bytes(b))
    status, text = verdict(edited)
    assert status == 1 and "the summary counts 2 /world messages, the file holds 1" in text


def test_a_chunk_removed_from_the_middle_names_the_first_missing_step(clean, tmp_path, capsys):
    data = clean.read_bytes()
    _, chunks = layout(clean)
    c = chunks[3]  # steps 20..29
    cut = tmp_path / "hole.mcap"
    cut.write_bytes(data[: c.record.start] + data[c.record.end :])
    status, out, _ = isaac(capsys, "replay", cut)
    assert status == 1
    assert out.startswith("DAMAGED at step 20: ")
    assert "steps 20..29 are missing (step 30 follows step 19)" in out
    # asked for, the steps before the hole are checked and the verdict says how many of how many
    status, out, _ = isaac(capsys, "replay", cut, "--partial")
    assert status == 0 and out.startswith(
        "partial: 20 of 51 steps checked, identical up to step 19"
    )


def test_the_last_chunk_zeroed_is_damage_at_its_first_step(clean, tmp_path, capsys):
    _, chunks = layout(clean)
    last = chunks[-1]  # step 50 alone
    b = bytearray(clean.read_bytes())
    b[last.data_start : last.data_end] = bytes(last.data_end - last.data_start)
    bad = tmp_path / "zeroed.mcap"
    bad.write_bytes(bytes(b))
    status, out, _ = isaac(capsys, "replay", bad)
    assert status == 1 and out.startswith("DAMAGED at step 50: 50 of 51 steps checked")
    assert "CRC" in out and f"at byte {last.record.start}" in out
    status, out, _ = isaac(capsys, "replay", bad, "--partial")
    assert status == 0
    assert out.startswith("partial: 50 of 51 steps checked, identical up to step 49")


def test_one_steps_bodies_message_dropped_is_named(clean, tmp_path, capsys):
    bad = rewrite(
        clean, tmp_path / "no_bodies.mcap", lambda ms: [m for m in ms if m[:2] != ("/bodies", 25)]
    )
    status, out, _ = isaac(capsys, "replay", bad)
    assert status == 1 and out.startswith("DAMAGED at step 25: 25 of 51 steps checked")
    assert "step 25 has no /bodies message" in out


def test_every_stats_message_dropped_leaves_nothing_to_compare(clean, tmp_path, capsys):
    bad = rewrite(clean, tmp_path / "no_stats.mcap", lambda ms: [m for m in ms if m[0] != "/stats"])
    status, out, err = isaac(capsys, "replay", bad)
    assert (status, out) == (2, "")
    assert "no complete step" in err and "step 0 has no /stats message" in err
    assert err.count("\n") == 1


def test_a_flipped_byte_with_a_stale_crc_is_damage_not_a_footnote(clean, tmp_path, capsys):
    _, chunks = layout(clean)
    c = chunks[2]  # steps 10..19
    b = bytearray(clean.read_bytes())
    b[(c.data_start + c.data_end) // 2] ^= 0x04
    bad = tmp_path / "flipped.mcap"
    bad.write_bytes(bytes(b))
    status, out, _ = isaac(capsys, "replay", bad)
    assert status == 1 and out.startswith("DAMAGED at step 10: 10 of 51 steps checked")
    assert "damaged: a chunk whose CRC does not match its data" in out


def test_a_partial_killed_before_its_first_chunk_is_unusable(tmp_path, capsys):
    partial = abandoned_log(tmp_path / "killed.mcap", steps=-1)  # header only
    status, out, err = isaac(capsys, "replay", partial)
    assert (status, out) == (2, "") and "holds no complete step" in err
    status, out, err = isaac(capsys, "replay", partial, "--partial")
    assert status == 2 and "holds no complete step" in err


def test_a_closed_log_with_a_missing_step_fails_diff_too(clean, tmp_path, capsys):
    bad = rewrite(clean, tmp_path / "gap.mcap", lambda ms: [m for m in ms if m[1] != 30])
    for a, b in ((clean, bad), (bad, clean)):
        status, out, _ = isaac(capsys, "diff", a, b)
        assert status == 1 and out.startswith("DAMAGED at step 30: "), out
        report = diff_logs(str(a), str(b), partial=True)
        assert report.verdict == "partial" and report.last_step == 29
    assert isaac(capsys, "diff", clean, rewrite(clean, tmp_path / "same.mcap"))[0] == 0


def test_inspect_and_recover_report_the_same_damage(clean, tmp_path, capsys):
    _, chunks = layout(clean)
    c = chunks[4]  # steps 30..39
    b = bytearray(clean.read_bytes())
    b[c.data_start + 5] ^= 0x80
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(b))
    status, out, _ = isaac(capsys, "inspect", bad)
    assert status == 0
    assert (
        f"damaged: from step 30: a chunk whose CRC does not match its data (corrupt), at byte "
        f"{c.record.start}" in out
    )
    assert "steps    30 of the 51 the log claims (step 0 to 29" in out
    fixed = tmp_path / "fixed.mcap"
    status, out, _ = isaac(capsys, "recover", bad, fixed)
    assert status == 0 and out.startswith(
        f"recovered 30 step(s) into {fixed}: stopped at step 29, the last step in the log"
    )
    assert "could not salvage: step 30 and after: a chunk whose CRC" in out
    assert "21 of the 51 steps it claims" in out
    # what was recovered is a whole log of its own: it claims the 30 steps it holds
    assert verdict(fixed)[0] == 0
    assert [s.step for s in LogReader(str(fixed)).steps()] == list(range(30))
    assert recover(str(clean), str(tmp_path / "copy.mcap")).lost is None


# every field of the /contacts message (format 2): the manifold fields, once per manifold, and
# the point fields; at step 50 of TINY under a full push-out: two manifolds of two points, the
# second pushed
_CONTACT_FIELDS = [
    (name, typ) for name, _n, typ, repeated in S.MESSAGES["Contacts"] if repeated
] + [("step", "uint64"), ("time", "double")]


@pytest.fixture(scope="module")
def pushed(tmp_path_factory) -> Path:
    from isaac.engine.simulation import Simulation
    from isaac.scene import load_scene_text
    from recorder import Recorder

    text = TINY.replace("  steps: 50\n", "  steps: 50\n  position_correction: full\n")
    sim = Simulation(load_scene_text(text, source="<tiny, full push-out>"))
    path = tmp_path_factory.mktemp("pushed") / "pushed.mcap"
    with Recorder(
        sim, mcap_path=str(path), flush_every=10, compression="none", offload="none"
    ) as rec:
        rec.write(sim.record())
        for r in sim.run(STEPS):
            rec.write(r)
    return path


@pytest.mark.parametrize("field,typ", _CONTACT_FIELDS, ids=[f for f, _ in _CONTACT_FIELDS])
def test_an_edit_to_any_manifold_or_point_field_is_caught(pushed, tmp_path, field, typ):
    k = STEPS
    seen = {}

    def change(d):
        assert list(d["points"]) == [2, 2]  # manifolds of two points: a second point is edited
        assert list(d["pushed"]) == [1]
        seen["before"] = d[field]
        if typ == "double" and field != "time":
            values = np.array(d[field])
            values[-1] = np.nextafter(values[-1], np.inf)  # one ULP (from 0.0: a subnormal)
            d[field] = values
        elif field == "time":
            d[field] = float(np.nextafter(d[field], np.inf))
        elif field == "step":
            d[field] = d[field] + 1
        elif field == "points":
            d[field] = np.array([1, 3], dtype=np.uint32)  # the same points, regrouped
        elif field == "pushed":
            d[field] = np.array([0], dtype=np.uint32)  # the push moved to the other manifold
        else:
            values = np.array(d[field])
            values[-1] += 1
            d[field] = values

    assert verdict(pushed)[0] == 0
    bad = rewrite(pushed, tmp_path / "bad.mcap", crafted("/contacts", k, change))
    assert "before" in seen
    status, text = verdict(bad)
    assert status in (1, 2), text
    assert f"step {k}" in text, text
    if status == 1 and field not in ("step", "points", "pushed", "a", "b"):
        report = replay_log(str(bad))
        d = report.divergences[0]
        assert (d.step, d.channel) == (k, "/contacts")
        assert d.field.split(".")[0] == field, d
        if typ == "double" and field != "time":
            assert d.ulps == 1 or d.logged == 0.0
