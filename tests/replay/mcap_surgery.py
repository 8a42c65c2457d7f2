"""Test helpers: a small recorded log, the byte layout of its records, and ways to damage it.

`small_log` records a 3-body scene for 50 steps in this process (chunks closed every 10 steps,
so the log holds 7 chunks); `layout` lists where each record starts and ends (from the file's
own bytes, walked with the MCAP record framing), so a mutation can aim at a chunk's data, its
header, the summary or the footer; `rewrite` copies a log through the mcap Writer with its
messages edited (so every CRC and the summary are consistent with the edit, and only what the
log claims in ``isaac.end`` is left as it was). The logs made here are uncompressed on purpose
(``compression="none"``; the recorder's default is lz4): a byte flipped or zeroed then lands in
a message's bytes, not in a compressed stream.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from isaac.engine.simulation import Simulation
from isaac.scene import load_scene_text
from recorder import Recorder
from recorder import schema as S
from recorder.mcap_records import McapScan, open_log

# a ground, a box resting on it and a triangle dropped onto the box: contacts from step ~20 on
TINY = """\
name: tiny
world:
  dt: 0.01
  steps: 50
bodies:
  - name: ground
    shape: {box: [10.0, 1.0]}
    position: [0.0, -0.5]
    concrete: true
  - name: box
    shape: {box: [1.0, 1.0]}
    position: [0.0, 0.5]
  - name: tri
    shape: {regular: {sides: 3, radius: 0.5}}
    position: [0.1, 1.6]
"""
STEPS = 50  # steps after step 0: the log holds steps 0..50
FLUSH_EVERY = 10


def small_log(path: Path, *, compression: str = "none", steps: int = STEPS) -> Path:
    """Record TINY to ``path`` in this process; chunks close after step 0, then every 10."""
    sim = Simulation(load_scene_text(TINY, source="<tiny>"))
    with Recorder(
        sim, mcap_path=str(path), flush_every=FLUSH_EVERY, compression=compression, offload="none"
    ) as rec:
        rec.write(sim.record())
        for r in sim.run(steps):
            rec.write(r)
    return path


def abandoned_log(path: Path, *, steps: int) -> Path:
    """What a SIGKILL leaves after ``steps`` steps (flushed chunks, no summary): the .partial.
    steps < 0: killed before its first chunk (the recorder writes step 0 as it starts, so the
    file is cut back to what came before that chunk: header, schemas, metadata)."""
    sim = Simulation(load_scene_text(TINY, source="<tiny>"))
    rec = Recorder(
        sim, mcap_path=str(path), flush_every=FLUSH_EVERY, compression="none", offload="none"
    )
    if steps >= 0:
        rec.write(sim.record())
        for r in sim.run(steps):
            rec.write(r)
    rec._abandon()
    partial = Path(str(path) + ".partial")
    if steps < 0:
        data = partial.read_bytes()
        at = 8  # past the magic: records are opcode (1 byte), length (uint64 LE), content
        while at < len(data) and data[at] != 0x06:  # 0x06: a Chunk
            at += 9 + struct.unpack_from("<Q", data, at + 1)[0]
        partial.write_bytes(data[:at])
    return partial


@dataclass(frozen=True)
class Record:
    opcode: int
    start: int  # offset of the opcode byte
    end: int  # offset just past the record


@dataclass(frozen=True)
class Chunk:
    record: Record
    data_start: int  # offset of the chunk's (compressed) data
    data_end: int
    first_step: int  # of the messages inside, from its message times (dt = 0.01 s)
    last_step: int


def layout(path: Path) -> tuple[list[Record], list[Chunk]]:
    """Every record of a clean log, and its chunks with where their data lies."""
    f, size = open_log(str(path))
    with f:
        scan = McapScan(f, size)
        records, chunks = [], []
        for offset, opcode, body in scan.records():
            rec = Record(opcode, offset, offset + 9 + len(body))
            records.append(rec)
            if opcode == 0x06:
                (clen,) = struct.unpack_from("<I", body, 28)
                data_start = offset + 9 + 32 + clen + 8
                start_ns, end_ns = struct.unpack_from("<QQ", body, 0)
                chunks.append(
                    Chunk(rec, data_start, rec.end, round(start_ns / 1e7), round(end_ns / 1e7))
                )
    return records, chunks


def summary_crc(data: bytearray) -> None:
    """Recompute the footer's summary CRC of ``data`` in place (an edit the CRC agrees with)."""
    footer = len(data) - 8 - 29
    summary_start, _offsets = struct.unpack_from("<QQ", data, footer + 9)
    crc = zlib.crc32(bytes(data[summary_start : footer + 9 + 16]))
    struct.pack_into("<I", data, footer + 9 + 16, crc)


def encode(message: str, d: dict) -> bytes:
    """Protobuf bytes of a decoded message dict (any array lengths: for crafting bad ones)."""
    parts = []
    for name, number, typ, repeated in S.spec(message):
        value = d[name]
        if typ.startswith("message:"):
            sub = typ.split(":", 1)[1]
            parts += [S.enc_bytes(number, encode(sub, item)) for item in value]
        elif repeated:
            enc = {"double": S.enc_doubles, "fixed32": S.enc_fixed32s, "bool": S.enc_bools}[typ]
            parts.append(enc(number, np.asarray(value)))
        elif typ == "double":
            parts.append(S.enc_double(number, value))
        elif typ == "string":
            parts.append(S.enc_string(number, value))
        else:
            parts.append(S.enc_uint(number, int(value)))
    return b"".join(parts)


def crafted(topic: str, step: int, change):
    """An `rewrite` edit that re-encodes ``topic`` at ``step`` after ``change(decoded dict)``."""

    def edit(messages):
        out = []
        for t, seq, time, data in messages:
            if (t, seq) == (topic, step):
                d = S.decode(S.TOPICS[topic], data)
                change(d)
                data = encode(S.TOPICS[topic], d)
            out.append((t, seq, time, data))
        return out

    return edit


def rewrite(src: Path, dst: Path, edit=None, *, end=None, meta=None) -> Path:
    """Copy the log ``src`` to ``dst`` through the mcap Writer, record by record.

    edit(list of (topic, sequence, log_time, data)) -> new list: the messages in file order.
    end(dict) -> dict | None: the new ``isaac.end`` metadata (None drops it); default unchanged.
    meta(dict) -> dict: the new ``isaac`` metadata; default unchanged.
    Schemas, channels, metadata (``isaac`` first, ``isaac.end`` after the last chunk, as the
    recorder writes them) and the attachment are kept, so the summary is consistent with the
    messages written; only ``isaac.end`` still says what the original log held.
    """
    f, size = open_log(str(src))
    with f:
        scan = McapScan(f, size)
        messages = [
            (scan.channels[m.channel_id].topic, m.sequence, m.log_time, bytes(m.data))
            for m in scan.messages()
        ]
    if edit is not None:
        messages = edit(messages)
    edit_meta = meta
    meta = {m.name: dict(m.metadata) for _o, m in scan.metadata}
    with open(dst, "wb") as out:
        w = Writer(out, chunk_size=4096, compression=CompressionType.NONE)
        w.start(profile="isaac", library="isaac-recorder")
        w.add_metadata("isaac", meta["isaac"] if edit_meta is None else edit_meta(meta["isaac"]))
        for _o, a in scan.attachments:
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        ids = {}
        for _cid, ch in sorted(scan.channels.items()):
            sc = scan.schemas[ch.schema_id]
            ids[ch.topic] = w.register_channel(
                ch.topic, ch.message_encoding, w.register_schema(sc.name, sc.encoding, sc.data)
            )
        for topic, seq, t, data in messages:
            w.add_message(ids[topic], t, data, t, seq)
        new_end = meta["isaac.end"] if end is None else end(dict(meta["isaac.end"]))
        if new_end is not None:
            w.add_metadata("isaac.end", new_end)
        w.finish()
    return dst
