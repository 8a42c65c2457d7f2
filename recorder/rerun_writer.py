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
- ``stats/<name>``: the `/stats` scalars as time series.
Steps are buffered and sent column-wise (``send_columns``) every ``batch`` steps.
Positions are float32 in Rerun: exact values live in the MCAP log only.
"""

from __future__ import annotations

import os

import numpy as np
import pyarrow as pa
import rerun as rr

from isaac.records import StepRecord

APP_ID = "isaac"
STAT_NAMES = ("kinetic_energy", "potential_energy", "total_energy", "linear_momentum_x",
              "linear_momentum_y", "angular_momentum", "contact_count", "max_depth",
              "max_impulse")

_MOVING = [70, 140, 230]
_CONCRETE = [150, 150, 150]
_POINT = [230, 50, 50]
_NORMAL = [240, 200, 40]
_PUSH = [40, 210, 210]
_IMPULSE = [220, 60, 220]


def default_scales(model) -> tuple[float, float]:
    """(impulse_scale m per N s, normal_length m) for drawing arrows.

    L = median body size (circumradius about the centre of mass), m = median moving mass: an
    impulse arrow L long changes a median body's speed by 1 m/s; normals are drawn L / 2 long.
    """
    local = np.asarray(model.vertices_local, dtype=np.float64)
    if local.size == 0:
        return 1.0, 0.5
    size = np.sqrt(np.max(np.sum(local * local, axis=2), axis=1))
    char_len = float(np.median(size))
    mass = np.asarray(model.mass, dtype=np.float64)
    concrete = np.asarray(model.concrete, dtype=bool)
    moving = mass[~concrete] if np.any(~concrete) else mass
    m_med = float(np.median(moving))
    return char_len / max(m_med * 1.0, 1e-12), 0.5 * char_len


_EMPTY2 = np.zeros((0, 2), dtype=np.float32)
_STRIP_TYPE = rr.components.LineStrip2DBatch._ARROW_DATATYPE


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


def _load_kernels() -> None:
    """Import and load the compiled batch kernels now (about 1 s the first time in a process),
    so that the first batch of a run does not wait for them."""
    from recorder.rerun_batch import contact_arrows, outlines

    outlines(np.zeros((1, 1)), np.zeros((1, 1, 2)), np.zeros(1, dtype=np.int64),
             np.zeros((1, 2, 2)), np.ones(1, dtype=np.int64))
    z2 = np.zeros((1, 2))
    contact_arrows(np.ones(1, dtype=np.int64), z2, z2, np.zeros(1), z2, z2, 1.0, 1.0)


class RerunLogWriter:
    """Writes one run to ``path`` (through ``path + '.partial'``).

    model: names, vertices_local (n, V, 2), vertex_count, mass, concrete (Simulation.model or a
        recorder.reader.WorldTable).
    scene: anything with ``.name`` and ``.world.dt`` (s).
    impulse_scale: m of arrow per N s; default: a median body size per (median mass * 1 m/s).
    normal_length: drawn length (m) of unit normals; default half a median body size.
    batch: steps buffered per ``send_columns``.
    """

    def __init__(self, path: str, model, scene, *, impulse_scale: float | None = None,
                 normal_length: float | None = None, batch: int = 100) -> None:
        self.path = str(path)
        self.partial_path = self.path + ".partial"
        self.model = model
        self.names = [str(x) for x in model.names]
        self.batch = batch
        counts = np.asarray(model.vertex_count, dtype=np.int64)
        local = np.asarray(model.vertices_local, dtype=np.float64)
        self.vertices_local = np.ascontiguousarray(local, dtype=np.float64)
        self.vertex_count = np.ascontiguousarray(counts, dtype=np.int64)
        self.concrete = np.asarray(model.concrete, dtype=bool)
        self._not_concrete = ~self.concrete
        auto_impulse, auto_normal = default_scales(model)
        self.impulse_scale = float(impulse_scale) if impulse_scale is not None else auto_impulse
        self.normal_length = float(normal_length) if normal_length is not None else auto_normal
        self._closed = False
        self._static_done = False
        self._last_labels_key: bytes | None = None
        self._moving_key: bytes | None = None
        self._reset()
        _load_kernels()

        self.rec = rr.RecordingStream(APP_ID, recording_id=f"isaac-{scene.name}")
        self.rec.save(self.partial_path)
        rec = self.rec
        rec.log("world", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
        rec.log("world/bodies/moving", rr.LineStrips2D.from_fields(colors=[_MOVING],
                                                                   radii=[-1.5]), static=True)
        rec.log("world/contacts", rr.Points2D.from_fields(colors=[_POINT], radii=[-3.0]),
                static=True)
        rec.log("world/normals", rr.Arrows2D.from_fields(colors=[_NORMAL]), static=True)
        rec.log("world/push", rr.Arrows2D.from_fields(colors=[_PUSH]), static=True)
        rec.log("world/impulses", rr.Arrows2D.from_fields(colors=[_IMPULSE]), static=True)
        rec.log("world/impulses", rr.AnyValues(impulse_scale_m_per_Ns=self.impulse_scale,
                                               normal_length_m=self.normal_length), static=True)
        rec.log("info", rr.TextDocument(
            f"# ISAAC run: {scene.name}\n\n"
            f"- physics frame: x right, y up (flipped once on `world`); units m, s, kg\n"
            f"- impulse arrows (`world/impulses`): {self.impulse_scale:.6g} m per N s\n"
            f"- normal arrows (`world/normals`): {self.normal_length:.6g} m long (unit normals,"
            f" from body a to body b)\n"
            f"- push arrows (`world/push`): true length (m), for body a and body b\n"
            f"- exact float64 data: the MCAP log\n", media_type=rr.MediaType.MARKDOWN),
            static=True)

    def _reset(self) -> None:
        """Start an empty batch (the buffers are kept and reused)."""
        self._count = 0  # steps in the batch
        self._rows = 0  # contact rows in the batch
        self._steps: list[int] = []
        self._times: list[float] = []
        self._moving: list[np.ndarray] = []  # moving bodies' indices per step (shared)
        self._stats_rows: list[int] = []  # the batch's steps that came with stats

    def _allocate(self, n: int) -> None:
        """Per-batch buffers for n bodies; the contact rows grow as needed (`_grow`)."""
        b = self.batch
        self._angle = np.empty((b, n))  # rad
        self._position = np.empty((b, n, 2))  # m, world
        self._stats = np.empty((b, len(STAT_NAMES)))
        self._counts = np.zeros(b, dtype=np.int64)  # contact rows per step
        self._contact_cap = 0
        self._grow(4 * n * b)  # a pile has 1-3 rows per body: rarely grown

    def _grow(self, rows: int) -> None:
        """Room for ``rows`` contact rows in the batch, keeping the ones buffered."""
        cap = max(rows, 2 * self._contact_cap)
        old = getattr(self, "_point", None)
        for name, shape in (("_point", (cap, 2)), ("_normal", (cap, 2)), ("_impulse", (cap,)),
                            ("_push_a", (cap, 2)), ("_push_b", (cap, 2))):
            new = np.empty(shape)
            if old is not None:
                new[:self._rows] = getattr(self, name)[:self._rows]
            setattr(self, name, new)
        self._contact_cap = cap

    def _batch_strips(self) -> tuple[np.ndarray, np.ndarray, list[int]]:
        """Closed float32 outlines of the buffered steps: their points (one strip after the
        other, no padding), the points per strip, and the strips per step; one compiled pass per
        run of steps with the same moving bodies."""
        from recorder.rerun_batch import outlines

        moving, count = self._moving, self._count
        points, lengths, counts = [], [], []
        i = 0
        while i < count:
            idx = moving[i]
            j = i + 1
            while j < count and moving[j] is idx:
                j += 1
            counts.extend([idx.size] * (j - i))
            if idx.size:
                points.append(outlines(self._angle[i:j], self._position[i:j], idx,
                                       self.vertices_local, self.vertex_count))
                lengths.append(np.tile(self.vertex_count[idx] + 1, j - i))
            i = j
        if not points:
            return _EMPTY2, np.zeros(0, dtype=np.int64), counts
        if len(points) == 1:
            return points[0], lengths[0], counts
        return np.concatenate(points), np.concatenate(lengths), counts

    def _outlines(self, angle: np.ndarray, position: np.ndarray,
                  mask: np.ndarray) -> list[np.ndarray]:
        """Closed float32 world outlines of the bodies in ``mask`` (one (c + 1, 2) array each),
        by the batches' kernel."""
        from recorder.rerun_batch import outlines

        idx = np.flatnonzero(mask)
        points = outlines(np.ascontiguousarray(angle, dtype=np.float64)[None],
                          np.ascontiguousarray(position, dtype=np.float64)[None], idx,
                          self.vertices_local, self.vertex_count)
        return np.split(points, np.cumsum(self.vertex_count[idx] + 1)[:-1])

    def write(self, record: StepRecord, stats: dict | None = None) -> None:
        """Buffer one step (its `/stats` values without the hash, or None to leave them out);
        sent column-wise every ``batch`` steps."""
        c = record.contacts
        values = (None if stats is None
                  else np.array([float(stats[k]) for k in STAT_NAMES], dtype=np.float64))
        self.append(record.step, record.time, record.position, record.angle, record.exists,
                    c.point, c.normal, c.impulse, c.push_a, c.push_b, values)

    def append(self, step: int, time: float, position: np.ndarray, angle: np.ndarray,
               exists: np.ndarray, point: np.ndarray, normal: np.ndarray, impulse: np.ndarray,
               push_a: np.ndarray, push_b: np.ndarray, stats: np.ndarray | None) -> None:
        """Buffer one step, copying its arrays (they may be reused once this returns).

        position (n, 2) m and angle (n,) rad, world; exists (n,) bool; per contact row: point
        (m, 2) m, unit normal (m, 2) from a to b, impulse (m,) N s, push_a, push_b (m, 2) m;
        stats: the nine `/stats` values in STAT_NAMES order, or None. `write` and the Rerun
        writer process (`recorder.writer_process.RerunFrame`) both come here.
        """
        rec = self.rec
        exists = np.asarray(exists, dtype=bool)
        if not self._static_done:
            concrete = self.concrete & exists
            if np.any(concrete):
                rec.log("world/bodies/concrete", rr.LineStrips2D(
                    self._outlines(angle, position, concrete), colors=[_CONCRETE], radii=[-1.5],
                    labels=[self.names[k] for k in np.flatnonzero(concrete)]), static=True)
            self._static_done = True
            self._allocate(int(exists.shape[0]))
        moving = exists & self._not_concrete
        key = moving.tobytes()
        if key != self._last_labels_key:
            # labels change only when a body enters or leaves: logged then, not every step
            rec.set_time("step", sequence=int(step))
            rec.set_time("sim_time", duration=float(time))
            rec.log("world/bodies/moving", rr.LineStrips2D.from_fields(
                labels=[self.names[k] for k in np.flatnonzero(moving)]))
            self._last_labels_key = key
        if key != self._moving_key:
            self._moving_key = key
            self._moving_index = np.flatnonzero(moving)
        k = self._count
        self._steps.append(int(step))
        self._times.append(float(time))
        self._moving.append(self._moving_index)
        # the outlines and arrows of a whole batch are computed in _send from these buffers,
        # a few compiled passes per batch instead of per step
        self._angle[k] = angle
        self._position[k] = position
        m = int(impulse.shape[0])
        self._counts[k] = m
        if m:
            lo = self._rows
            if lo + m > self._contact_cap:
                self._grow(lo + m)
            self._point[lo:lo + m] = point
            self._normal[lo:lo + m] = normal
            self._impulse[lo:lo + m] = impulse
            self._push_a[lo:lo + m] = push_a
            self._push_b[lo:lo + m] = push_b
            self._rows = lo + m
        if stats is not None:
            self._stats[k] = stats
            self._stats_rows.append(k)
        self._count = k + 1
        if self._count >= self.batch:
            self._send()

    def _send(self) -> None:
        if not self._count:
            return
        rec = self.rec
        count, rows = self._count, self._rows
        times = [rr.TimeColumn("step", sequence=self._steps),
                 rr.TimeColumn("sim_time", duration=self._times)]
        points, lengths, strip_counts = self._batch_strips()
        rec.send_columns("world/bodies/moving", indexes=times,
                         columns=rr.LineStrips2D.columns(
                             strips=_strips_arrow(points, lengths)).partition(strip_counts))
        counts = self._counts[:count]
        if rows:
            from recorder.rerun_batch import contact_arrows

            points, normals, impulses, push_pt, push_v, push_counts = contact_arrows(
                counts, self._point[:rows], self._normal[:rows], self._impulse[:rows],
                self._push_a[:rows], self._push_b[:rows], self.normal_length,
                self.impulse_scale)
        else:
            points = normals = impulses = push_pt = push_v = _EMPTY2
            push_counts = np.zeros(count, dtype=np.int64)
        rec.send_columns("world/contacts", indexes=times,
                         columns=rr.Points2D.columns(positions=points).partition(counts))
        rec.send_columns("world/normals", indexes=times,
                         columns=rr.Arrows2D.columns(origins=points, vectors=normals)
                         .partition(counts))
        rec.send_columns("world/impulses", indexes=times,
                         columns=rr.Arrows2D.columns(origins=points, vectors=impulses)
                         .partition(counts))
        rec.send_columns("world/push", indexes=times,
                         columns=rr.Arrows2D.columns(origins=push_pt, vectors=push_v)
                         .partition(push_counts))
        with_stats = self._stats_rows
        if with_stats:
            stat_times = times
            if len(with_stats) < count:  # some steps came without stats
                stat_times = [rr.TimeColumn("step", sequence=[self._steps[k] for k in with_stats]),
                              rr.TimeColumn("sim_time",
                                            duration=[self._times[k] for k in with_stats])]
            values = self._stats[with_stats]
            for j, name in enumerate(STAT_NAMES):
                rec.send_columns(f"stats/{name}", indexes=stat_times,
                                 columns=rr.Scalars.columns(scalars=values[:, j].copy()))
        self._reset()

    def settle(self) -> None:
        """Wait until the data already sent (whole batches) is written to the file; the steps
        of the open batch stay buffered."""
        self.rec.flush()

    def close(self, *, complete: bool = True, stopped_at: int | None = None,
              reason: str | None = None) -> str:
        """Send what is buffered, note an early stop in the recording, finish and rename."""
        if self._closed:
            return self.path
        self._closed = True
        last = self._steps[-1] if self._steps else None
        self._send()
        if not complete:
            at = stopped_at if stopped_at is not None else last
            if at is not None:
                self.rec.set_time("step", sequence=int(at))
            self.rec.log("log", rr.TextLog(
                f"run stopped at step {at}" + (f": {reason}" if reason else ""),
                level=rr.TextLogLevel.WARN))
        self.rec.flush()
        self.rec.disconnect()
        os.replace(self.partial_path, self.path)
        return self.path

    def abandon(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                self._send()
                self.rec.flush()
                self.rec.disconnect()
            except Exception:  # noqa: BLE001 - best effort
                pass


def mcap_to_rrd(mcap_path: str, rrd_path: str, **kwargs) -> str:
    """Convert an ISAAC MCAP log (clean or partial) to a Rerun recording; returns ``rrd_path``."""
    from types import SimpleNamespace

    from recorder.reader import LogReader

    log = LogReader(mcap_path)
    scene = SimpleNamespace(name=log.metadata.get("scene_name", "log"),
                            world=SimpleNamespace(dt=log.dt))
    writer = RerunLogWriter(rrd_path, log.world, scene, **kwargs)
    try:
        for logged in log.steps():
            writer.write(logged.record, logged.stats)
    except BaseException:
        writer.abandon()
        raise
    end = log.end or {}
    complete = log.closed_cleanly and end.get("complete") == "true"
    return writer.close(complete=complete, reason=None if complete else end.get("reason")
                        or "the log was not closed")
