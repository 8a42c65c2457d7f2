"""Write an ISAAC run as a Rerun recording (.rrd): for looking, not the source of truth.

Layout (docs/log-format.md, "Rerun"):
- timelines ``step`` (sequence) and ``sim_time`` (duration, s);
- ``world``: static ``Transform3D(scale=[1, -1, 1])``: physics is y-up, Rerun's 2D views y-down;
- ``world/bodies/concrete``: concrete bodies' outlines, logged once as static;
- ``world/bodies/moving``: one closed strip per existing moving body per step (world frame, m),
  with the body names as labels (logged at step 0 and whenever a body enters or leaves);
- ``world/contacts``: contact points; ``world/normals``: unit normals (drawn ``normal_length`` m
  long); ``world/push``: the non-zero push-out displacements of a and b, at the point (true
  length, m);
  ``world/impulses``: ``j * n`` at the point, ``impulse_scale`` m per N s (the scale is stored
  in the recording as AnyValues on ``world/impulses`` and in the ``info`` text document);
- ``world/joints/lines``: one 2-point strip per joint whose bodies exist, from its world anchor
  on body a to its anchor on body b (m); ``world/joints/anchors``: those anchors as points (a
  revolute joint's two coincide: its pivot);
- ``stats/<name>``: the `/stats` scalars as time series.
Outlines, arrows and joints are computed by compiled kernels (`recorder.rerun_batch`) into the
open batch's float32 buffers: a whole `StepBatch` in one call (`write_batch`, with its stats and
its never-write-NaN check in another), or one step as it arrives (`write`, `append`: the Rerun
writer process's frames); the batch is sent column-wise (``send_columns``) every ``batch`` steps,
from a thread of its own in the Rerun writer process.
Positions are float32 in Rerun: exact values live in the MCAP log only.
"""

from __future__ import annotations

import queue
import threading

import numpy as np

from isaac.engine.records import CONTACT_FIELDS, StepRecord
from isaac.errors import LogError
from recorder import blueprint
from recorder.blueprint import STAT_NAMES
from recorder.pack import batch_state, model_bundle, read_only
from recorder.rerun_batch import (
    AT_JOINTS,
    AT_POINTS,
    AT_PUSHES,
    AT_ROWS,
    AT_STRIPS,
    JOINTS,
    PUSHES,
    ROWS,
    STRIPS,
    Buffers,
    Drawing,
    batch_stats,
    draw_steps,
    step_outlines,
)
from recorder.shapes import drawn_shapes, joint_geometry

__all__ = ["STAT_NAMES", "PUSH_SCALE", "RerunLogWriter", "default_scales", "mcap_to_rrd"]


def default_scales(model) -> tuple[float, float]:
    """(impulse_scale m per N s, normal_length m) for drawing arrows.

    L = median body size (circumradius about the centre of mass), m = median moving mass: an
    impulse arrow L long changes a median body's speed by 1 m/s; normals are drawn L / 2 long.
    Push arrows: `PUSH_SCALE`.
    """
    local, _ = drawn_shapes(model)  # a circle's size is its radius
    if local.size == 0:
        return 1.0, 0.5
    size = np.sqrt(np.max(np.sum(local * local, axis=2), axis=1))
    char_len = _median(size)
    mass = np.asarray(model.mass, dtype=np.float64)
    concrete = np.asarray(model.concrete, dtype=bool)
    moving = mass[~concrete] if np.any(~concrete) else mass
    m_med = _median(moving)
    return char_len / max(m_med * 1.0, 1e-12), 0.5 * char_len


def _median(values: np.ndarray) -> float:
    """`np.median` of a non-empty 1-D array, the same value (the middle one, or the mean of the
    two middle ones), without the `numpy.ma` import `np.median`'s first call costs (8-24 ms of
    a short recorded run)."""
    s = np.sort(values)
    n = len(s)
    return float(s[n // 2]) if n % 2 else float((s[n // 2 - 1] + s[n // 2]) / 2)


# push-out displacements are drawn this many times their length: one of 1 % of a median body
# size (L above) is drawn as long as a normal (L / 2). True length, they were a few pixels long
# (the default scene's pushes are 3e-6 to 5e-3 m, its bodies about 0.4 m across) and only
# appeared as bodies landed; at rest they are zero and none are drawn.
PUSH_SCALE = 50.0


def _load_kernels() -> None:
    """Load the compiled kernels now (compiled the first time: about 1 s), so that the
    first steps of a run do not wait for them."""
    z1, z2, f2 = np.zeros(1), np.zeros((1, 2)), np.zeros((4, 2), dtype=np.float32)
    one = np.ones(1, dtype=np.int64)
    idx = np.zeros(1, dtype=np.int64)
    step_outlines(read_only(z1), read_only(z2), idx, np.zeros((1, 2, 2)), one, f2, 0)
    i0 = np.zeros(0, dtype=np.int64)
    d = Drawing(np.zeros((1, 2, 2)), one, np.ones(1, bool), i0, i0, z2[:0], z2[:0], np.ones(3))
    out = Buffers(
        f2, np.zeros(2, np.int32), f2, f2, f2, f2, f2, f2, np.zeros((1, 4), np.int64),
        np.zeros(6, np.int64),
    )  # fmt: skip
    row = np.zeros((0, 2))
    args = [z1[None], z2[None], np.ones((1, 1), bool), np.zeros(2, np.int64), row, row, z1[:0]]
    args += [row, row]
    # read-only, as every caller hands them (`recorder.pack.read_only`): one compile
    draw_steps(*map(read_only, args), d, out)


class _RunSummary:
    """What the summary text says about the steps sent so far (updated once per batch)."""

    def __init__(self) -> None:
        self.steps = 0
        self.first: int | None = None
        self.last: int | None = None
        self.energy_first: float | None = None  # total (kinetic + potential), J
        self.energy_last: float | None = None
        self.max_depth = (0.0, None)  # (m, step)
        self.max_impulse = (0.0, None)  # (N s, step)
        self.contact_rows = 0

    def add(self, steps: list[int], stats: np.ndarray, stats_rows: list[int]) -> None:
        """A batch: its steps, and its `/stats` rows (STAT_NAMES order) for steps[stats_rows]."""
        if not steps:
            return
        self.steps += len(steps)
        self.first = steps[0] if self.first is None else self.first
        self.last = steps[-1]
        if not stats_rows:
            return
        col = {name: stats[:, j] for j, name in enumerate(STAT_NAMES)}
        if self.energy_first is None:
            self.energy_first = float(col["total_energy"][0])
        self.energy_last = float(col["total_energy"][-1])
        self.contact_rows += int(np.sum(col["contact_count"]))
        for attr, name in (("max_depth", "max_depth"), ("max_impulse", "max_impulse")):
            k = int(np.argmax(col[name]))  # the first step of the batch's largest
            if getattr(self, attr)[1] is None or col[name][k] > getattr(self, attr)[0]:
                setattr(self, attr, (float(col[name][k]), steps[stats_rows[k]]))


class RerunLogWriter:
    """Writes one run to ``path`` (through ``path + '.partial'``).

    model: names, vertices_local (n, V, 2), vertex_count, mass, concrete (Simulation.model or a
        recorder.reader.WorldTable).
    scene: anything with ``.name`` and ``.world.dt`` (s).
    impulse_scale: m of arrow per N s; default: a median body size per (median mass * 1 m/s).
    normal_length: drawn length (m) of unit normals; default half a median body size.
    push_scale: push-out arrows are drawn this many times their true length (`PUSH_SCALE`).
    batch: steps buffered per ``send_columns``.
    background: send each finished batch from a thread of its own (the Rerun writer process
        does, so that the steps behind a batch are taken at once); otherwise in the caller.
    joints: the joint table (rows with a, b, local_a, local_b; `recorder.shapes.joint_geometry`),
        default ``model.joints``: each joint is drawn as a line between its bodies' anchors,
        the anchors marked (a revolute joint's coincide: its pivot).
    sender: what makes the object that does the ``rr.*`` calls, called with the ``.partial``
        path, the recording id and the drawing scales; default
        `recorder.rerun_send.open_sender` (rerun-sdk in this process); `isaac run` passes a
        `RerunSendProcess`'s ``open``.
    """

    def __init__(
        self,
        path: str,
        model,
        scene,
        *,
        impulse_scale: float | None = None,
        normal_length: float | None = None,
        push_scale: float = PUSH_SCALE,
        batch: int = 100,
        background: bool = False,
        joints=None,
        sender=None,
    ) -> None:

        self.path = str(path)
        self.partial_path = self.path + ".partial"
        self.model = model
        self.names = [str(x) for x in model.names]
        self.batch = batch
        local, counts = drawn_shapes(model)  # circles as a ring with a spoke
        self.vertices_local = np.ascontiguousarray(local, dtype=np.float64)
        self.vertex_count = np.ascontiguousarray(counts, dtype=np.int64)
        self.concrete = np.asarray(model.concrete, dtype=bool)
        self._not_concrete = ~self.concrete
        auto_impulse, auto_normal = default_scales(model)
        self.impulse_scale = float(impulse_scale) if impulse_scale is not None else auto_impulse
        self.normal_length = float(normal_length) if normal_length is not None else auto_normal
        self.push_scale = float(push_scale)
        self.scene_name = str(scene.name)
        self.dt = float(scene.world.dt)
        gravity = getattr(scene.world, "gravity", None)
        # (gx, gy) m/s^2 for the stats of whole batches; None: only steps given with their stats
        self.gravity = None if gravity is None else tuple(float(g) for g in gravity)
        joint_a, joint_b, local_a, local_b = joint_geometry(model, joints)
        self.joint_count = len(joint_a)
        self._moving_points = int(np.sum(self.vertex_count[self._not_concrete] + 1))
        self._moving_count = int(np.sum(self._not_concrete))  # bodies drawn each step, at most
        self._drawing = Drawing(
            self.vertices_local, self.vertex_count, np.ascontiguousarray(self._not_concrete),
            joint_a, joint_b, local_a, local_b,
            np.array([self.normal_length, self.impulse_scale, self.push_scale]),
        )  # fmt: skip
        self._stats_model = model_bundle(model)  # (mass, inertia, concrete)
        self._summary = _RunSummary()
        self._closed = False
        self._sent_last: int | None = None  # the last step of the batches sent
        self._static_done = False
        self._last_labels_key: bytes | None = None
        self._reset()
        _load_kernels()
        self._error: BaseException | None = None
        self._queue: queue.Queue | None = None
        self._thread: threading.Thread | None = None

        # the recording stream, its layout and static entities (recorder.rerun_send): in this
        # process, or in the sender process `isaac run` started (RerunSendProcess.open)
        if sender is None:
            from recorder.rerun_send import open_sender as sender
        self._sender = sender(
            self.partial_path,
            f"isaac-{scene.name}",
            impulse_scale=self.impulse_scale,
            normal_length=self.normal_length,
            push_scale=self.push_scale,
            joints=self.joint_count > 0,
            moving=self._moving_count,
        )
        self._log_info()
        if background:
            # two batches in flight at most (a few MB each); a third waits for the first
            self._queue = queue.Queue(maxsize=2)
            self._thread = threading.Thread(
                target=self._work, name="isaac-rerun-sender", daemon=True
            )
            self._thread.start()

    def _log_info(self, state: str = "recording (not closed yet)") -> None:
        """The ``info`` text beside the view: the run's summary so far, the legend, the
        scales; logged static at the start and again when the recording is closed (the viewer
        keeps the last)."""
        g = "{:.6g}".format
        s = self._summary
        n, concrete = len(self.names), int(np.sum(self.concrete))
        lines = [f"# ISAAC run: {self.scene_name}", "", f"**{state}**", ""]
        lines += [blueprint.legend_markdown(self.joint_count > 0), "", "## Run", ""]
        lines.append(f"- {n} bodies ({concrete} concrete), dt = {g(self.dt)} s")
        if s.first is not None:
            lines.append(
                f"- {s.steps} steps recorded: {s.first} to {s.last} "
                f"(t = {g(s.first * self.dt)} to {g(s.last * self.dt)} s)"
            )
        if s.energy_first is not None:
            lines.append(
                f"- energy (kinetic + potential): {g(s.energy_first)} J at the start, "
                f"{g(s.energy_last)} J at the end"
            )
            for what, (value, at), unit in (
                ("depth", s.max_depth, "m"),
                ("impulse", s.max_impulse, "N s"),
            ):
                where = "" if at is None else f" (step {at})"
                lines.append(f"- largest {what} {g(value)} {unit}{where}")
            lines.append(f"- contact rows, all steps: {s.contact_rows}")
        lines += [
            "",
            "## Scales",
            "",
            "- physics frame: x right, y up (flipped once on `world`); m, s, kg",
            f"- impulse arrows: j n, {g(self.impulse_scale)} m per N s",
            f"- normals: unit, from body a to body b, drawn {g(self.normal_length)} m long",
            f"- push-out arrows (body a and body b): {g(self.push_scale)} x their length",
            "- a body's label is `INDEX:NAME`, INDEX the log's body index "
            "(as in `isaac inspect LOG --step K`)",
            "- positions here are float32; exact float64 values: the MCAP log",
        ]
        self._sender.info("\n".join(lines) + "\n")

    def _label(self, k: int) -> str:
        """A body's label: its log index and name (the strips' instance index is not the body
        index: only existing moving bodies are drawn)."""
        return f"{k}:{self.names[k]}"

    def _reset(self) -> None:
        """Start an empty batch."""
        self._count = 0  # steps in the batch
        self._steps: list[int] = []
        self._times: list[float] = []
        self._stats_rows: list[int] = []  # the batch's steps that came with stats
        self._buffers_sent = True  # Rerun may still read the last batch's arrays: new ones

    def _new_buffers(self) -> None:
        """Fresh arrays for a batch, sized like the last one's (they grow as needed); fresh
        because Rerun takes the arrays it is sent without copying and encodes them later, in
        its own threads."""

        b = self.batch
        if not hasattr(self, "_caps"):
            moving = self._moving_count
            # a pile has 1-3 contact rows per body: rarely grown (untouched pages cost nothing)
            # (outline points, strips, contact rows, joint anchors)
            self._caps = [b * self._moving_points, b * moving, 4 * b * len(self.names)]
            self._caps.append(2 * b * self.joint_count)
        points, strips, rows, joints = self._caps
        f32 = lambda k: np.empty((k, 2), dtype=np.float32)  # noqa: E731
        self._out = Buffers(
            f32(points), np.empty(strips, dtype=np.int32), f32(rows), f32(rows), f32(rows),
            f32(2 * rows), f32(2 * rows), f32(joints), np.zeros((b, 4), dtype=np.int64),
            np.zeros(6, dtype=np.int64),
        )  # fmt: skip
        self._stats = np.empty((b, len(STAT_NAMES)))
        self._buffers_sent = False

    def _make_room(self, steps: int, rows: int) -> None:
        """Room in the batch's buffers for ``steps`` more steps holding ``rows`` contact rows,
        keeping what is buffered."""

        if self._buffers_sent:
            self._new_buffers()
        out = self._out
        at = out.at
        caps = self._caps
        need = (
            int(at[AT_POINTS]) + steps * self._moving_points,
            int(at[AT_STRIPS]) + steps * self._moving_count,
            int(at[AT_ROWS]) + rows,
            int(at[AT_JOINTS]) + 2 * steps * self.joint_count,
        )
        if need[0] <= caps[0] and need[1] <= caps[1] and need[2] <= caps[2] and need[3] <= caps[3]:
            return
        self._caps = [max(c, n, 2 * c if n > c else c) for n, c in zip(need, self._caps)]
        points, strips, rows_cap, joints = self._caps

        def grown(old, cap):
            if old.shape[0] >= cap:
                return old
            new = np.empty((cap, *old.shape[1:]), dtype=old.dtype)
            new[: old.shape[0]] = old
            return new

        self._out = Buffers(
            grown(out.strips, points), grown(out.strip_len, strips), grown(out.points, rows_cap),
            grown(out.normals, rows_cap), grown(out.impulses, rows_cap),
            grown(out.push_pt, 2 * rows_cap), grown(out.push_v, 2 * rows_cap),
            grown(out.joints, joints), out.per_step, out.at,
        )  # fmt: skip

    def _outlines(
        self, angle: np.ndarray, position: np.ndarray, mask: np.ndarray
    ) -> list[np.ndarray]:
        """Closed float32 world outlines of the bodies in ``mask`` (one (c + 1, 2) array each),
        by the steps' kernel."""

        idx = np.flatnonzero(mask)
        sizes = self.vertex_count[idx] + 1
        points = np.empty((int(sizes.sum()), 2), dtype=np.float32)
        step_outlines(  # read-only, whoever's arrays they are: one compile
            read_only(np.ascontiguousarray(angle, dtype=np.float64)),
            read_only(np.ascontiguousarray(position, dtype=np.float64)),
            idx,
            self.vertices_local,
            self.vertex_count,
            points,
            0,
        )
        return np.split(points, np.cumsum(sizes)[:-1])

    def write(self, record: StepRecord, stats: dict | None = None) -> None:
        """Buffer one step (its `/stats` values without the hash, or None to leave them out);
        sent column-wise every ``batch`` steps."""
        c = record.contacts
        values = (
            None
            if stats is None
            else np.array([float(stats[k]) for k in STAT_NAMES], dtype=np.float64)
        )
        self.append(
            record.step,
            record.time,
            record.position,
            record.angle,
            record.exists,
            c.point,
            c.normal,
            c.impulse,
            c.push_a,
            c.push_b,
            values,
        )

    def _log_static(self, angle: np.ndarray, position: np.ndarray, exists: np.ndarray) -> None:
        """The concrete bodies' outlines, once, at their first step's poses."""
        concrete = self.concrete & exists
        if np.any(concrete):
            self._sender.concrete(
                self._outlines(angle, position, concrete),
                [self._label(k) for k in np.flatnonzero(concrete)],
            )
        self._static_done = True

    def _log_labels(self, step: int, time: float, moving: np.ndarray) -> None:
        """The moving bodies' labels from ``step`` on: logged when a body enters or leaves, not
        every step. moving: (n,) bool, the moving bodies that exist."""
        key = moving.tobytes()
        if key == self._last_labels_key:
            return
        self._sender.labels(step, time, [self._label(k) for k in np.flatnonzero(moving)])
        self._last_labels_key = key

    def append(
        self,
        step: int,
        time: float,
        position: np.ndarray,
        angle: np.ndarray,
        exists: np.ndarray,
        point: np.ndarray,
        normal: np.ndarray,
        impulse: np.ndarray,
        push_a: np.ndarray,
        push_b: np.ndarray,
        stats: np.ndarray | None,
    ) -> None:
        """Buffer one step: what it draws is computed now (`recorder.rerun_batch.draw_steps`,
        a batch of one) into the batch's float32 buffers, so the arrays given may be reused
        once this returns.

        position (n, 2) m and angle (n,) rad, world; exists (n,) bool; per contact row: point
        (m, 2) m, unit normal (m, 2) from a to b, impulse (m,) N s, push_a, push_b (m, 2) m;
        stats: the nine `/stats` values in STAT_NAMES order, or None. `write` and the Rerun
        writer process (`recorder.frames.RerunFrame`) both come here.
        """

        exists = np.asarray(exists, dtype=bool)
        if not self._static_done:
            self._log_static(angle, position, exists)
        self._log_labels(step, time, exists & self._not_concrete)
        m = int(impulse.shape[0])
        self._make_room(1, m)
        k = self._count
        self._steps.append(int(step))
        self._times.append(float(time))

        def c(a):  # read-only, as a batch's arrays: the kernel compiles once
            return read_only(np.ascontiguousarray(a))

        draw_steps(
            c(angle)[None], c(position)[None], c(exists)[None], c(np.array([0, m], np.int64)),
            c(point), c(normal), c(impulse), c(push_a), c(push_b), self._drawing, self._out,
        )  # fmt: skip
        if stats is not None:
            self._stats[k] = stats
            self._stats_rows.append(k)
        self._count = k + 1
        if self._count >= self.batch:
            self._send()

    @property
    def takes_batches(self) -> bool:
        """Whether `write_batch` may be given whole batches: it computes their stats, which
        needs the scene's gravity."""
        return self.gravity is not None

    def write_batch(self, batch) -> int:
        """Buffer the steps of an `isaac.engine.records.StepBatch`: their stats and what they
        draw computed over the whole batch by two compiled calls (`recorder.rerun_batch`:
        `batch_stats` checks every float on the way, `draw_steps`), and sent every ``batch``
        steps as columns. Returns how many steps were taken: all, or those before the first one
        holding a NaN or an infinity (the caller says which; nothing of it is drawn)."""

        rows = dict(zip(CONTACT_FIELDS, batch.row_arrays))
        stats = np.empty((batch.steps, len(STAT_NAMES)))
        good = batch_stats(
            self._stats_model, self.gravity, batch_state(batch), batch.offsets,
            tuple(batch.row_arrays), stats,
        )  # fmt: skip
        if good and not self._static_done:
            self._log_static(batch.angle[0], batch.position[0], batch.exists[0])
        steps = batch.first + np.arange(good)
        times = steps * batch.dt  # a record's time: step * dt
        moving = batch.exists[:good] & self._not_concrete
        if good:
            # labels where the moving bodies change (and at the first step, if not logged)
            changed = np.flatnonzero(np.any(moving[1:] != moving[:-1], axis=1)) + 1
            for s in (0, *changed.tolist()):
                self._log_labels(int(steps[s]), float(times[s]), moving[s])
        lo = 0
        offsets = batch.offsets
        while lo < good:
            hi = min(good, lo + self.batch - self._count)
            self._make_room(hi - lo, int(offsets[hi] - offsets[lo]))
            k = self._count
            draw_steps(
                batch.angle[lo:hi], batch.position[lo:hi], batch.exists[lo:hi],
                offsets[lo : hi + 1], rows["point"], rows["normal"], rows["impulse"],
                rows["push_a"], rows["push_b"], self._drawing, self._out,
            )  # fmt: skip
            self._steps.extend(steps[lo:hi].tolist())
            self._times.extend(times[lo:hi].tolist())
            self._stats[k : k + hi - lo] = stats[lo:hi]
            self._stats_rows.extend(range(k, k + hi - lo))
            self._count = k + hi - lo
            if self._count >= self.batch:
                self._send()
            lo = hi
        return good

    def _send(self) -> None:
        """Close the open batch and send it (with ``background``: hand it to the thread)."""

        if not self._count:
            return
        self._check()
        count = self._count
        out = self._out
        at = out.at
        per_step = out.per_step[:count]
        stats = self._stats[self._stats_rows]
        self._summary.add(self._steps, stats, self._stats_rows)
        # what _send_batch uses: the batch's own arrays (new ones are made for the next)
        job = (
            self._steps,
            self._times,
            out.strips[: at[AT_POINTS]],
            out.strip_len[: at[AT_STRIPS]],
            per_step[:, STRIPS].copy(),
            out.points[: at[AT_ROWS]],
            out.normals[: at[AT_ROWS]],
            out.impulses[: at[AT_ROWS]],
            per_step[:, ROWS].copy(),
            out.push_pt[: at[AT_PUSHES]],
            out.push_v[: at[AT_PUSHES]],
            per_step[:, PUSHES].copy(),
            out.joints[: at[AT_JOINTS]],
            per_step[:, JOINTS].copy(),
            stats,
            self._stats_rows,
        )
        self._sent_last = self._steps[-1]  # once per batch: where a late warning is logged
        self._reset()
        if self._queue is None:
            self._send_batch(*job)
        else:
            self._queue.put(job)

    def _send_batch(self, *job) -> None:
        """Send one batch (the arrays `_send` took, in its order): outlines, contacts, arrows,
        joints, stats (`recorder.rerun_send.RerunSender.batch`)."""
        self._sender.batch(*job)

    def _work(self) -> None:
        """The sender thread: batches in order; after a failure, it only drains the queue
        (the error is raised in the caller's next call)."""
        assert self._queue is not None
        while True:
            job = self._queue.get()
            try:
                if job is None:
                    return
                if self._error is None:
                    self._send_batch(*job)
            except BaseException as exc:  # noqa: BLE001 - reported to the caller
                self._error = exc
            finally:
                self._queue.task_done()

    def _check(self) -> None:
        if self._error is not None:
            raise LogError(f"writing {self.partial_path} failed: {self._error}")

    def _stop_worker(self) -> None:
        if self._thread is not None:
            self._queue.put(None)
            self._thread.join()
            self._thread = None

    def settle(self) -> None:
        """Wait until the data already sent (whole batches) is written to the file; the steps
        of the open batch stay buffered."""
        if self._queue is not None:
            self._queue.join()
        self._check()
        self._sender.flush()

    def close(
        self, *, complete: bool = True, stopped_at: int | None = None, reason: str | None = None
    ) -> str:
        """Send what is buffered, note an early stop in the recording, finish and rename."""
        if self._closed:
            return self.path
        self._closed = True
        last = self._steps[-1] if self._steps else None
        try:
            self._send()
        finally:
            self._stop_worker()
        if self._error is not None:
            self._sender.abandon()  # the .partial file stays, as after a crash
            self._check()
        if complete:
            self._log_info("run complete")
        else:
            at = stopped_at if stopped_at is not None else last
            stopped = f"run stopped at step {at}" + (f": {reason}" if reason else "")
            self._log_info(stopped)
            self._sender.warn(at, stopped)
        # flushed, closed and renamed (by a sender process: answered once it is)
        return self._sender.finish(self.path)

    def abandon(self, reason: str | None = None) -> None:
        """Write out what is buffered and close the recording without renaming it (the .partial
        file stays). reason: also log it as a warning at the last step (a writer process whose
        run died: recorder.writer_process)."""
        if not self._closed:
            self._closed = True
            try:
                try:
                    self._send()
                finally:
                    self._stop_worker()
                if reason is not None and self._error is None:
                    self._log_info(f"not closed: {reason}")
                    self._sender.warn(self._sent_last, reason)
                self._sender.abandon()
            except Exception:  # noqa: BLE001 - best effort
                pass


def mcap_to_rrd(mcap_path: str, rrd_path: str, **kwargs) -> str:
    """Convert an ISAAC MCAP log (clean or partial) to a Rerun recording; returns ``rrd_path``."""
    from types import SimpleNamespace

    from recorder.reader import LogReader

    log = LogReader(mcap_path)
    scene = SimpleNamespace(
        name=log.metadata.get("scene_name", "log"), world=SimpleNamespace(dt=log.dt)
    )
    writer = RerunLogWriter(rrd_path, log.world, scene, **kwargs)
    try:
        for logged in log.steps():
            writer.write(logged.record, logged.stats)
    except BaseException:
        writer.abandon()
        raise
    end = log.end or {}
    complete = log.closed_cleanly and end.get("complete") == "true"
    return writer.close(
        complete=complete,
        reason=None if complete else end.get("reason") or "the log was not closed",
    )
