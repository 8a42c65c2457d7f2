"""`identical` covers what the tools show and what other MCAP readers use, not only the steps.

The embedded scene (checked against its sha256) is what a replay simulates from; the `isaac`
metadata restates it (``settings``, each ``world.<key>``, ``dt``, ``gravity``, ``bodies``,
``scene_name``), and an edit there replayed ``identical`` with no note, or with a note only,
while ``isaac inspect`` showed the edited values. The MessageIndex records after each chunk,
which ISAAC does not read but seeking readers use to find a message, were not checked at all;
nor were the summary's statistics beyond its counts of messages and chunks, its attachment index
or its summary offsets. Each edit below must now replay DAMAGED (exit 1) and name the byte.
"""

from __future__ import annotations

import json
import struct
import sys
from io import BytesIO
from pathlib import Path

import pytest
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import MessageIndex

from isaac.app.cli import main
from recorder.mcap_records import McapScan, open_log
from replay.compare import replay_log
from replay.report import format_text

sys.path.insert(0, str(Path(__file__).parent))
from mcap_surgery import layout, rewrite, small_log, summary_crc  # noqa: E402

OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_STATISTICS, OP_SUMMARY_OFFSET = 0x07, 0x08, 0x0B, 0x0E


@pytest.fixture(scope="module")
def clean(tmp_path_factory) -> Path:
    return small_log(tmp_path_factory.mktemp("covers") / "tiny.mcap")


def verdict(path: Path) -> tuple[int, str]:
    report = replay_log(str(path))
    return report.exit_status, format_text(report)


def edited(clean: Path, tmp: Path, name: str, change) -> Path:
    b = bytearray(clean.read_bytes())
    change(b)
    out = tmp / name
    out.write_bytes(bytes(b))
    return out


def replace_once(b: bytearray, old: bytes, new: bytes, *, after: bytes = b"") -> None:
    """Replace the first ``old`` after ``after`` with ``new`` (same length: no record moves)."""
    assert len(old) == len(new)
    at = b.index(old, b.index(after) if after else 0)
    b[at : at + len(old)] = new


def metadata_offset(clean: Path) -> int:
    records, _ = layout(clean)
    return next(r.start for r in records if r.opcode == 0x0C)


def test_the_untouched_log_is_identical(clean):
    status, text = verdict(clean)
    assert status == 0 and text.startswith("identical: replayed 51 steps"), text
    assert "note" not in text


def test_a_flipped_flat_setting_is_damage(clean, tmp_path):
    # world.position_iterations "3" -> "2": the replay simulates the embedded scene's 3
    bad = edited(
        clean,
        tmp_path,
        "flat.mcap",
        lambda b: replace_once(b, b"3", b"2", after=b"world.position_iterations"),
    )
    status, text = verdict(bad)
    assert status == 1, text
    assert text.startswith(f"DAMAGED at byte {metadata_offset(clean)}: 51 of 51 steps checked")
    assert "world.position_iterations 2, the embedded scene 3" in text


def test_an_edited_settings_json_is_damage_and_inspect_shows_the_scenes(clean, tmp_path, capsys):
    # the settings JSON's dt 0.01 -> 0.02 (the flat copies and the scene still say 0.01)
    bad = edited(
        clean,
        tmp_path,
        "settings.mcap",
        lambda b: replace_once(b, b'"dt": 0.01', b'"dt": 0.02', after=b"settings"),
    )
    status, text = verdict(bad)
    assert status == 1 and text.startswith("DAMAGED at byte"), text
    assert "settings say dt 0.02, the embedded scene 0.01" in text
    assert main(["inspect", str(bad)]) == 0
    out = capsys.readouterr().out
    assert "dt 0.01 s" in out and "0.02" in out.split("damaged:")[1]
    assert "settings say dt 0.02, the embedded scene 0.01" in out
    # recover writes the metadata as the recorder writes it from the scene: a clean log again
    fixed = tmp_path / "fixed.mcap"
    assert main(["recover", str(bad), str(fixed)]) == 0
    assert "rewrote the metadata from the embedded scene" in capsys.readouterr().out
    assert verdict(fixed)[0] == 0


@pytest.mark.parametrize(
    "key,old,new",
    [("dt", b"0.01", b"0.02"), ("bodies", b"3", b"4"), ("scene_name", b"tiny", b"tinx")],
)
def test_each_copy_of_the_scene_in_the_metadata_is_checked(clean, tmp_path, key, old, new):
    # the metadata value follows its key: u32 length of the key, the key, u32 length, value
    def change(b):
        at = b.index(struct.pack("<I", len(key)) + key.encode()) + 4 + len(key) + 4
        assert bytes(b[at : at + len(old)]) == old
        b[at : at + len(old)] = new

    status, text = verdict(edited(clean, tmp_path, f"{key}.mcap", change))
    assert status == 1 and f"says {key} " in text, text


def test_a_setting_another_version_does_not_know_is_a_note(clean, tmp_path):
    # a log whose recorder had no `contact_points` setting: both copies lack it alike
    def older(meta):
        settings = json.loads(meta["settings"])
        del settings["contact_points"]
        out = {k: v for k, v in meta.items() if k != "world.contact_points"}
        out["settings"] = json.dumps(settings, sort_keys=True)
        return out

    status, text = verdict(rewrite(clean, tmp_path / "older.mcap", meta=older))
    assert status == 0, text
    assert "reads the embedded scene's world settings differently" in text
    assert "contact_points" in text


def test_a_flipped_message_index_is_damage(clean, tmp_path):
    records, _ = layout(clean)
    indexes = [r for r in records if r.opcode == OP_MESSAGE_INDEX]
    assert len(indexes) == 7 * 3 + 1  # /bodies, /contacts, /stats a chunk; /world once
    wrong = []
    # each index record: its channel id, an entry's log time and an entry's offset
    for k, r in enumerate(indexes):
        body = r.start + 9
        (size,) = struct.unpack_from("<I", clean.read_bytes(), body + 2)
        assert size >= 16
        for what, at in (("channel", body), ("log time", body + 6), ("offset", body + 6 + 8)):
            bad = edited(
                clean, tmp_path, f"mi{k}.mcap", lambda b, at=at: b.__setitem__(at, b[at] ^ 1)
            )
            status, text = verdict(bad)
            if status != 1 or "message ind" not in text or "byte" not in text.split(":")[0]:
                wrong.append(f"record at {r.start}, {what}: {text.splitlines()[0]}")
    assert not wrong, "\n".join(wrong)


def test_the_message_indexes_read_as_the_mcap_library_reads_them(clean):
    # the second reader: the library's chunk indexes point at MessageIndex records whose
    # entries are the checker's (each message's log time and offset in its chunk)
    with open(clean, "rb") as f:
        summary = make_reader(f).get_summary()
        data = clean.read_bytes()
        f2, size = open_log(str(clean))
        with f2:
            scan = McapScan(f2, size)
            for _ in scan.messages():
                pass
        assert scan.index_error is None
        for k, ci in enumerate(summary.chunk_indexes):
            assert ci.message_index_offsets == scan.message_indexes[k]
            for cid, offset in ci.message_index_offsets.items():
                (length,) = struct.unpack_from("<Q", data, offset + 1)
                body = BytesIO(data[offset + 9 : offset + 9 + length])
                mi = MessageIndex.read(ReadDataStream(body))
                assert mi.channel_id == cid and len(mi.records) > 0


def _summary_edit(clean, tmp_path, name, opcode, at, pack):
    records, _ = layout(clean)
    r = next(r for r in records if r.opcode == opcode)

    def change(b):
        fmt, delta = pack
        value = struct.unpack_from(fmt, b, r.start + 9 + at)[0]
        struct.pack_into(fmt, b, r.start + 9 + at, value + delta)
        summary_crc(b)  # an edit the summary's CRC agrees with

    return edited(clean, tmp_path, name, change)


@pytest.mark.parametrize(
    "name,opcode,at,pack,said",
    [
        # ChunkIndex: 4 u64, then the message index offsets (u32 length, u16 id, u64 offset)
        ("index offset", OP_CHUNK_INDEX, 32 + 4 + 2, ("<Q", 8), "message index offsets"),
        # Statistics: message count u64, then schema count u16, channel count u32
        ("schema count", OP_STATISTICS, 8, ("<H", 1), "schemas"),
        ("channel count", OP_STATISTICS, 10, ("<I", 1), "channels"),
        ("end time", OP_STATISTICS, 8 + 2 + 4 * 4 + 8, ("<Q", 1), "last message time"),
        # SummaryOffset: group opcode u8, group start u64
        ("summary offset", OP_SUMMARY_OFFSET, 1, ("<Q", 1), "summary offset"),
    ],
)
def test_a_summary_a_seeking_reader_would_trust_is_checked(
    clean, tmp_path, name, opcode, at, pack, said
):
    bad = _summary_edit(clean, tmp_path, name.replace(" ", "_") + ".mcap", opcode, at, pack)
    status, text = verdict(bad)
    assert status == 1 and said in text, text
