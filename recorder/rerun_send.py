"""The sending half of the Rerun writer: every ``rr.*`` call of a recording, and nothing else.

`recorder.rerun_writer.RerunLogWriter` (the drawing half) turns states and contacts into float32
line strips, points and arrows, one batch of steps at a time, and hands them here as plain
arrays and strings; `RerunSender` builds the recording stream, its blueprint and static layout,
and sends the batches (``send_columns``) to the ``.partial`` file.

Why two halves: importing rerun-sdk costs 0.4-0.5 s of CPU and sending a batch runs Python
code that holds the GIL. `isaac run --rrd` runs this module in a child process of its own
(`recorder.writer_process.RerunSendProcess`, started by `recorder.spawn` before the engine is
imported), so that both overlap the simulation; ``--offload none`` (and the Rerun writer
process of ``--offload process``) call `RerunSender` in the same process. The file's entity
data is the same either way.

This module imports only rerun-sdk, numpy, pyarrow and `recorder.blueprint`: the child never
imports numba or the engine.

Child protocol (``python -m recorder.rerun_send CMD_FD REPLY_FD [PREOPEN_JSON]``, the last the
`RerunSender` arguments when the parent knew them at the start): each command is a pickled
tuple ``(method, args)`` preceded by its length (8 bytes, little-endian): ``open`` first (the
`RerunSender` arguments), then any `RerunSender` method, ``flush`` (answered ``S``), ``close``
(finish and rename; answered ``D`` once the file is closed and renamed, then the child exits)
or ``abandon`` (write out what arrived and keep the ``.partial``). Replies: one byte, ``K``
ready (rerun imported), ``S`` flushed, ``D`` done, ``E`` failed followed by a 4-byte length and
the UTF-8 message. When the command pipe ends without ``close`` (the parent died), the child
writes out every batch that arrived, notes in the recording that the run was abandoned, and
leaves the ``.partial`` file. The child exits with ``os._exit`` once its file is closed: the
interpreter's teardown (0.1-0.2 s) would only delay the parent, which waits for it.
"""

from __future__ import annotations

import os

if __name__ == "__main__":
    # the sender process itself: no cyclic collection while it imports rerun-sdk (50-60 ms of
    # collections, of an import of 0.45-0.55 s, over objects that live as long as the
    # process); the module's end freezes them out of later collections (`gc.freeze`)
    import gc

    gc.disable()

import numpy as np  # noqa: E402 - after the collector is paused
import pyarrow as pa  # noqa: E402
import rerun as rr  # noqa: E402

from recorder import blueprint  # noqa: E402
from recorder.blueprint import STAT_NAMES  # noqa: E402

APP_ID = "isaac"

# a scene with more moving bodies than this gets their labels on hover only (drawn, they hide
# the scene)
LABELS_DRAWN_UP_TO = 12

_STRIP_TYPE = rr.components.LineStrip2DBatch._ARROW_DATATYPE
_VEC2_TYPE = rr.components.Position2DBatch._ARROW_DATATYPE
assert _VEC2_TYPE == rr.components.Vector2DBatch._ARROW_DATATYPE

# what the child writes into a file whose parent died without closing it
ABANDONED = "abandoned: the recording process ended without closing the log"


def _strips_arrow(points: np.ndarray, lengths: np.ndarray) -> pa.Array:
    """Strips of ``lengths`` points each, one after the other in ``points`` (float32, (p, 2)),
    as Rerun's LineStrip2D arrow array, built in one go.

    Rerun's own conversion walks the strips in Python (one call per strip); this builds the
    same array (list of fixed-size [x, y] float32 lists) from offsets and one flat buffer.
    """
    flat = pa.array(np.ascontiguousarray(points, dtype=np.float32).reshape(-1))
    inner = pa.FixedSizeListArray.from_arrays(flat, type=_STRIP_TYPE.value_type)
    offsets = np.zeros(len(lengths) + 1, dtype=np.int32)
    np.cumsum(lengths, out=offsets[1:])
    return pa.ListArray.from_arrays(pa.array(offsets), inner, type=_STRIP_TYPE)


def _column(descriptor, batch_type, values: pa.Array, counts: np.ndarray) -> rr.ComponentColumn:
    """A `send_columns` column of ``values`` (arrow, already of ``batch_type``'s type) with
    ``counts[k]`` of them at step k: what ``rr.<Archetype>.columns(...).partition(counts)``
    builds, without Rerun converting the data again in Python."""
    offsets = np.zeros(len(counts) + 1, dtype=np.int32)
    np.cumsum(counts, out=offsets[1:])
    return rr.ComponentColumn(descriptor, batch_type(values), offsets=offsets)


def _time_columns(steps: list[int], sim_times: list[float]) -> list[rr.TimeColumn]:
    """The ``step`` and ``sim_time`` (s) time columns of a batch's steps, converted in one go:
    ``sim_time`` as integer nanoseconds rounded as `rr.set_time` rounds a float of seconds
    (Rerun's own conversion of a float array truncates; of a list, a Python call a step)."""
    nanos = np.rint(np.asarray(sim_times, dtype=np.float64) * 1e9).astype(np.int64)
    return [
        rr.TimeColumn("step", sequence=np.asarray(steps, dtype=np.int64)),
        rr.TimeColumn("sim_time", duration=nanos.astype("timedelta64[ns]")),
    ]


def _vec2(points: np.ndarray) -> pa.Array:
    """(k, 2) float32 as Rerun's Vec2D arrow array (fixed-size lists of 2), without a copy."""
    return pa.FixedSizeListArray.from_arrays(pa.array(points.reshape(-1)), type=_VEC2_TYPE)


def _arrows(vectors: pa.Array, origins: pa.Array, counts: np.ndarray) -> list:
    """An Arrows2D entity's columns, in the order ``Arrows2D.columns`` gives: vectors, then
    origins (both Vec2D arrow arrays, ``counts[k]`` arrows at step k)."""
    return [
        _column(rr.Arrows2D.descriptor_vectors(), rr.components.Vector2DBatch, vectors, counts),
        _column(rr.Arrows2D.descriptor_origins(), rr.components.Position2DBatch, origins, counts),
    ]


class RerunSender:
    """One recording stream writing ``partial_path``: the layout and static entities at once
    (what the scene alone decides), then the drawing scales (`scales`, which need the model)
    and what `RerunLogWriter` hands over. `open_sender` does the first two in one go.

    recording_id: Rerun's recording id (``isaac-<scene name>``).
    joints: whether the run has joints (their entities' static styles are logged).
    moving: the number of moving bodies (their labels are drawn only up to LABELS_DRAWN_UP_TO).
    """

    def __init__(self, partial_path: str, recording_id: str, *, joints: bool, moving: int) -> None:
        self.partial_path = partial_path
        self.last_step: int | None = None  # the last step of the batches sent
        self.joints = joints
        # what the sender process compares with the recording it is asked to open
        self.key = (partial_path, recording_id, bool(joints), int(moving))
        self.rec = rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
        rec.save(partial_path)
        # the layout (recorder.blueprint), made active: the same on every load
        rec.send_blueprint(blueprint.blueprint(), make_active=True, make_default=True)
        rec.log("world", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        rec.log("world", blueprint.annotation_context(), static=True)
        # colours come from the annotation context through the class ids (one per entity)
        many = moving > LABELS_DRAWN_UP_TO
        rec.log(
            "world/bodies/moving",
            rr.LineStrips2D.from_fields(
                class_ids=[blueprint.MOVING.class_id],
                radii=[-1.5],
                draw_order=10.0,
                show_labels=False if many else None,
            ),
            static=True,
        )
        # the overlays' class labels stay off: drawn beside every point or arrow of a step
        # with few of them, they covered small bodies (the car's wheels); hovering names them
        rec.log(
            "world/contacts",
            rr.Points2D.from_fields(
                class_ids=[blueprint.CONTACT.class_id],
                radii=[-2.5],
                draw_order=40.0,
                show_labels=False,
            ),
            static=True,
        )
        for kind in (blueprint.NORMAL, blueprint.IMPULSE, blueprint.PUSH):
            rec.log(
                f"world/{kind.entity}",
                rr.Arrows2D.from_fields(
                    class_ids=[kind.class_id],
                    radii=[-1.5 if kind is blueprint.PUSH else -1.0],
                    draw_order=30.0 if kind is blueprint.PUSH else 20.0,
                    show_labels=False,
                ),
                static=True,
            )
        if joints:
            # above the bodies' outlines, below the contact arrows and points
            rec.log(
                f"world/{blueprint.JOINT.entity}",
                rr.LineStrips2D.from_fields(
                    class_ids=[blueprint.JOINT.class_id],
                    radii=[-2.0],
                    draw_order=25.0,
                    show_labels=False,
                ),
                static=True,
            )
            rec.log(
                f"world/{blueprint.ANCHOR.entity}",
                rr.Points2D.from_fields(
                    class_ids=[blueprint.ANCHOR.class_id],
                    radii=[-4.0],
                    draw_order=35.0,
                    show_labels=False,
                ),
                static=True,
            )
        for name in STAT_NAMES:
            rec.log(f"stats/{name}", blueprint.series_style(name), static=True)

    def scales(self, impulse_scale: float, normal_length: float, push_scale: float) -> None:
        """The drawing scales, static AnyValues on ``world/impulses``: impulse_scale m of arrow
        per N s, normal_length m (a unit normal's drawn length), push_scale (push-out arrows'
        drawn length over their true one)."""
        self.rec.log(
            "world/impulses",
            rr.AnyValues(
                impulse_scale_m_per_Ns=impulse_scale,
                normal_length_m=normal_length,
                push_scale=push_scale,
            ),
            static=True,
        )

    def info(self, markdown: str) -> None:
        """The ``info`` text beside the view (static: the viewer keeps the last one logged)."""
        self.rec.log(
            "info", rr.TextDocument(markdown, media_type=rr.MediaType.MARKDOWN), static=True
        )

    def concrete(self, outlines: list[np.ndarray], labels: list[str]) -> None:
        """The concrete bodies' closed outlines (float32 (c + 1, 2) each, world, m), static."""
        self.rec.log(
            "world/bodies/concrete",
            rr.LineStrips2D(
                outlines,
                radii=[-3.0],
                labels=labels,
                class_ids=[blueprint.CONCRETE.class_id],
                draw_order=5.0,
            ),
            static=True,
        )

    def labels(self, step: int, time: float, labels: list[str]) -> None:
        """The moving bodies' labels from ``step`` (time ``time`` s) on."""
        self.rec.set_time("step", sequence=int(step))
        self.rec.set_time("sim_time", duration=float(time))
        self.rec.log("world/bodies/moving", rr.LineStrips2D.from_fields(labels=labels))

    def warn(self, step: int | None, text: str) -> None:
        """A warning in the ``log`` entity at ``step`` (None: the time last set)."""
        if step is not None:
            self.rec.set_time("step", sequence=int(step))
        self.rec.log("log", rr.TextLog(text, level=rr.TextLogLevel.WARN))

    def batch(
        self,
        steps,
        sim_times,
        strips,
        lengths,
        strip_counts,
        points,
        normals,
        impulses,
        counts,
        push_pt,
        push_v,
        push_counts,
        joints,
        joint_counts,
        stats,
        stats_rows,
    ) -> None:
        """Send one batch (`RerunLogWriter._send`'s arrays): outlines, contacts, arrows, joints,
        stats."""
        rec = self.rec
        count = len(steps)
        times = _time_columns(steps, sim_times)
        rec.send_columns(
            "world/bodies/moving",
            indexes=times,
            columns=[
                _column(
                    rr.LineStrips2D.descriptor_strips(),
                    rr.components.LineStrip2DBatch,
                    _strips_arrow(strips, lengths),
                    strip_counts,
                )
            ],
        )
        points = _vec2(points)
        rec.send_columns(
            "world/contacts",
            indexes=times,
            columns=[
                _column(
                    rr.Points2D.descriptor_positions(),
                    rr.components.Position2DBatch,
                    points,
                    counts,
                )
            ],
        )
        for entity, vectors in (("world/normals", normals), ("world/impulses", impulses)):
            rec.send_columns(entity, indexes=times, columns=_arrows(_vec2(vectors), points, counts))
        rec.send_columns(
            "world/push", indexes=times, columns=_arrows(_vec2(push_v), _vec2(push_pt), push_counts)
        )
        if self.joints:
            # each joint a 2-point strip from a's anchor to b's; the anchors as points
            rec.send_columns(
                f"world/{blueprint.JOINT.entity}",
                indexes=times,
                columns=[
                    _column(
                        rr.LineStrips2D.descriptor_strips(),
                        rr.components.LineStrip2DBatch,
                        _strips_arrow(joints, np.full(len(joints) // 2, 2, dtype=np.int32)),
                        joint_counts,
                    )
                ],
            )
            rec.send_columns(
                f"world/{blueprint.ANCHOR.entity}",
                indexes=times,
                columns=[
                    _column(
                        rr.Points2D.descriptor_positions(),
                        rr.components.Position2DBatch,
                        _vec2(joints),
                        2 * joint_counts,
                    )
                ],
            )
        if stats_rows:
            stat_times = times
            if len(stats_rows) < count:  # some steps came without stats
                stat_times = _time_columns(
                    [steps[k] for k in stats_rows], [sim_times[k] for k in stats_rows]
                )
            ones = np.ones(len(stats_rows), dtype=np.int64)
            for j, name in enumerate(STAT_NAMES):
                rec.send_columns(
                    f"stats/{name}",
                    indexes=stat_times,
                    columns=[
                        _column(
                            rr.Scalars.descriptor_scalars(),
                            rr.components.ScalarBatch,
                            pa.array(stats[:, j].copy()),
                            ones,
                        )
                    ],
                )
        if count:
            self.last_step = int(steps[-1])

    def flush(self) -> None:
        """Block until everything sent so far is written to the file."""
        self.rec.flush()

    def finish(self, path: str) -> str:
        """Write everything out, close the file and rename the ``.partial`` to ``path``."""
        self.rec.flush()
        self.rec.disconnect()
        os.replace(self.partial_path, path)
        return path

    def abandon(self, reason: str | None = None) -> None:
        """Write everything out and close the file, keeping the ``.partial``; reason: also a
        warning at the last step sent."""
        try:
            if reason is not None:
                self.warn(self.last_step, reason)
            self.rec.flush()
        finally:
            self.rec.disconnect()


def open_sender(
    partial_path: str,
    recording_id: str,
    *,
    impulse_scale: float,
    normal_length: float,
    push_scale: float,
    joints: bool,
    moving: int,
) -> RerunSender:
    """A `RerunSender` with its scales logged: what `RerunLogWriter` calls its ``sender``."""
    sender = RerunSender(partial_path, recording_id, joints=joints, moving=moving)
    sender.scales(impulse_scale, normal_length, push_scale)
    return sender


# -- child process -----------------------------------------------------------------------------
_LENGTH = 8  # bytes of a command's length prefix (little-endian)


def _read_exactly(fd: int, n: int) -> bytes | None:
    """n bytes from ``fd``, or None when the pipe ended first (the parent is gone)."""
    parts, got = [], 0
    while got < n:
        chunk = os.read(fd, min(n - got, 1 << 20))
        if not chunk:
            return None
        parts.append(chunk)
        got += len(chunk)
    return b"".join(parts)


def child_main(cmd_fd: int, rep_fd: int) -> int:
    """The child: read commands, send them to the file; see the module docstring. A
    ``prepare`` command (`recorder.spawn.WriterChild.prepare`, sent as soon as the parent has
    read the scene) makes the stream, its layout and static entities while the parent is still
    building the model; the ``open`` command that agrees with them only adds the scales."""
    import pickle
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the run loop, which closes
    parent_gone = False

    def reply(data: bytes) -> None:
        nonlocal parent_gone
        if parent_gone:
            return
        view = memoryview(data)
        try:
            while view:
                view = view[os.write(rep_fd, view) :]
        except BrokenPipeError:  # the parent died: its commands still go into the file
            parent_gone = True

    sender = None
    try:
        reply(b"K")
        while True:
            head = _read_exactly(cmd_fd, _LENGTH)
            body = None if head is None else _read_exactly(cmd_fd, int.from_bytes(head, "little"))
            if body is None:  # the parent is gone without closing: keep what arrived
                if sender is not None:
                    sender.abandon(ABANDONED)
                return 0
            method, args = pickle.loads(body)
            if method == "prepare":  # sent by `recorder.spawn.WriterChild.prepare`
                if sender is None:
                    sender = RerunSender(**args[0])
            elif method == "open":
                (partial_path, recording_id), header = args
                scales = [header.pop(k) for k in ("impulse_scale", "normal_length", "push_scale")]
                key = (partial_path, recording_id, bool(header["joints"]), int(header["moving"]))
                if sender is None or sender.key != key:  # not made beforehand, or otherwise
                    if sender is not None:
                        sender.abandon()
                    sender = RerunSender(partial_path, recording_id, **header)
                sender.scales(*scales)
            elif method == "flush":
                sender.flush()
                reply(b"S")
            elif method == "close":
                sender.finish(*args)
                sender = None
                reply(b"D")
                return 0
            elif method == "abandon":
                sender.abandon(*args)
                sender = None
                return 0
            else:
                getattr(sender, method)(*args)
    except BaseException as exc:  # noqa: BLE001 - reported to the parent in one line
        msg = " ".join(f"{type(exc).__name__}: {exc}".split()).encode()
        reply(b"E" + len(msg).to_bytes(4, "little") + msg)
        if sender is not None:
            try:
                sender.abandon()
            except Exception:  # noqa: BLE001 - best effort; the error is already reported
                pass
        return 1


if __name__ == "__main__":
    import sys

    gc.freeze()  # what the imports made: never collected, never scanned again
    gc.enable()
    code = child_main(int(sys.argv[1]), int(sys.argv[2]))
    # the file is closed (or abandoned and flushed): skip the interpreter's teardown
    sys.stderr.flush()
    os._exit(code)
