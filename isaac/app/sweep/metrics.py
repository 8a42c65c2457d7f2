"""What a sweep measures of each run, from the simulation's own step batches (docs/sweep-format.md
defines each column).

`Measure` sees the initial record and then every `StepBatch` the run yields, and keeps a few
numbers: nothing here re-simulates or re-derives physics beyond the engine's diagnostics
(energies, and the energy check of isaac.engine.energy_check) and the tunneling test that
`isaac tradeoff` uses (the segment each body's centre travels in a step, clipped against the
concrete polygons).
"""

from __future__ import annotations

import math

import numpy as np

# name -> what it is (the columns each adds: `columns`)
METRICS = {
    "final_state": "the state the run ended in",
    "max_depth": "largest penetration of any contact point",
    "energy_drift": "change of kinetic + potential energy",
    "contacts": "contact points seen",
    "tunneled": "moving bodies whose centre passed through a concrete body",
}

# paths x concrete bodies below which every path is clipped against every body (the bounding
# boxes that spare most of the clipping cost more than they spare for a few hundred paths)
PREFILTER_PATHS = 4096

_BODY_FIELDS = (
    ("x", "position", 0),
    ("y", "position", 1),
    ("angle", "angle", None),
    ("vx", "velocity", 0),
    ("vy", "velocity", 1),
    ("omega", "angular_velocity", None),
)


def columns(metrics, final_bodies) -> list:
    """The table's metric columns (pyarrow.Field), in order, for these metrics and bodies."""
    import pyarrow as pa  # only where a table is made: `isaac --help` does without it

    out: list[pa.Field] = []
    for name in metrics:
        if name == "final_state":
            out += [
                pa.field("final_step", pa.int64()),
                pa.field("final_state_hash", pa.string()),
                pa.field("final_com_x", pa.float64()),
                pa.field("final_com_y", pa.float64()),
            ]
            for body in final_bodies:
                out += [pa.field(f"final.{body}.{f}", pa.float64()) for f, _, _ in _BODY_FIELDS]
        elif name == "max_depth":
            out.append(pa.field("max_depth", pa.float64()))
        elif name == "energy_drift":
            out += [pa.field("energy_drift", pa.float64()), pa.field("energy_change", pa.float64())]
            out += [pa.field("energy_rose", pa.bool_()), pa.field("energy_rose_step", pa.int64())]
        elif name == "contacts":
            out += [pa.field("contacts", pa.int64()), pa.field("contact_steps", pa.int64())]
        elif name == "tunneled":
            out += [pa.field("tunneled", pa.int64()), pa.field("tunneled_bodies", pa.string())]
    return out


class Measure:
    """The metrics of one run, fed the initial record (`__init__`) and then each batch."""

    def __init__(self, sim, metrics, final_bodies) -> None:
        from isaac.app.tradeoff.trajectory import (
            _concrete_comes_and_goes,
            _concrete_discs,
            _concrete_planes,
            _kept_apart,
        )

        self.metrics = tuple(metrics)
        self.final_bodies = tuple(final_bodies)
        self.model = sim.model
        self.gravity = sim.scene.world.gravity
        first = sim.record()
        self.first = first
        self.last = first
        self.max_depth = 0.0
        self.contacts = 0
        self.contact_steps = 0
        self.movable = ~np.asarray(self.model.concrete)
        # concrete bodies never move: their edges in the world frame, once
        tunneling = "tunneled" in self.metrics
        self.planes = _concrete_planes(self.model, sim.state) if tunneling else []
        self.discs = _concrete_discs(self.model, sim.state) if tunneling else []
        # the concrete bodies of `planes` and of `discs`, in their orders, and the bodies each
        # may not collide with (None: it may with every one; the rule `isaac tradeoff` applies)
        model = self.model
        self.plane_bodies = np.flatnonzero(model.concrete & (model.vertex_count > 1))
        self.disc_bodies = np.flatnonzero(model.concrete & (model.vertex_count == 1))
        self.plane_apart = [_kept_apart(model, c) if tunneling else None for c in self.plane_bodies]
        self.disc_apart = [_kept_apart(model, c) if tunneling else None for c in self.disc_bodies]
        # some concrete body enters or leaves: a path counts only while it exists
        self.timed_concrete = tunneling and _concrete_comes_and_goes(model)
        self.pairwise = self.timed_concrete or any(
            x is not None for x in self.plane_apart + self.disc_apart
        )
        self._state0 = sim.state
        self._boxes = None
        self.tunneled = np.zeros(self.model.n_bodies, dtype=bool)
        self.energy = None
        if "energy_drift" in self.metrics:
            from isaac.engine import diagnostics
            from isaac.engine.energy_check import EnergyCheck

            e0 = diagnostics.summary(self.model, first, self.gravity)
            motors = bool(self.model.joints.has_motor.any())
            start = e0.kinetic_energy + e0.potential_energy
            self.energy = EnergyCheck.of(self.model, first, self.gravity, start, motors=motors)

    def add(self, batch) -> None:
        """Take the records of `batch` (isaac.StepBatch), in order."""
        counts = np.diff(np.asarray(batch.offsets, dtype=np.int64))
        total = int(counts.sum())
        self.contacts += total
        self.contact_steps += int(np.count_nonzero(counts))
        if total:
            # every contact row of the batch at once (a max is exact in any order)
            self.max_depth = max(self.max_depth, float(batch.all_contacts().depth.max()))
        if self.planes or self.discs:
            self._tunneling(batch)
        if self.energy is not None:
            from isaac.engine import diagnostics

            self.energy.add(*diagnostics.batch_energies(self.model, self.last, batch, self.gravity))
        self.last = batch.record(batch.steps - 1)

    def _bounds(self) -> list:
        """The box that bounds each concrete body (widened far past rounding): a centre's path
        whose own box misses it misses the polygon, so only the paths that meet it need be
        clipped (the same answer; in a pile the bodies rest beside the walls, and few paths
        come near them). One box per concrete polygon, in `_concrete_planes`' order."""
        if self._boxes is None:
            self._boxes = []
            state = self._state0
            for i in np.flatnonzero(self.model.concrete & (self.model.vertex_count > 1)):
                k = int(self.model.vertex_count[i])
                angle = float(state.angle[i])
                c, s = math.cos(angle), math.sin(angle)  # as _concrete_planes turns them
                rot = np.array([[c, -s], [s, c]])
                verts = self.model.vertices_local[i, :k] @ rot.T + state.position[i]
                pad = 1e-6 * (1.0 + float(np.abs(verts).max()))
                self._boxes.append((verts.min(axis=0) - pad, verts.max(axis=0) + pad))
        return self._boxes

    def _tunneling(self, batch) -> None:
        """Mark the bodies whose centre's path in a step of `batch` crossed a concrete body
        that could have stopped it: one that existed at both ends of the step, whose collision
        filter lets the pair collide, and that no joint connects to the body (unless the joint
        says `collide_connected`). A wheel on an axle has its centre inside the concrete hub in
        every step, and a body whose mask leaves out a concrete ledge falls through it, by
        design: neither is a tunnel."""
        from isaac.app.tradeoff.trajectory import _crossed_concrete

        n = self.model.n_bodies
        p1 = np.asarray(batch.position)
        p0 = np.concatenate([np.asarray(self.last.position)[None], p1[:-1]])
        e1 = np.asarray(batch.exists)
        e0 = np.concatenate([np.asarray(self.last.exists)[None], e1[:-1]])
        a, b = p0.reshape(-1, 2), p1.reshape(-1, 2)  # path k: step k // n, body k % n
        prefilter = a.shape[0] * len(self.planes) >= PREFILTER_PATHS
        if not prefilter and not self.pairwise:  # few paths, every pair may collide: one call
            crossed = _crossed_concrete(self.planes, a, b, self.discs)
            crossed = crossed.reshape(-1, n) & e0 & e1 & self.movable
            self.tunneled |= crossed.any(axis=0)
            return
        x0, x1 = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
        y0, y1 = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
        boxes = self._bounds() if prefilter else [None] * len(self.planes)
        crossed = np.zeros(a.shape[0], dtype=bool)
        for plane, box, c, apart in zip(self.planes, boxes, self.plane_bodies, self.plane_apart):
            if box is None:
                near = np.arange(a.shape[0])
            else:
                b_lo, b_hi = box
                near = (x1 >= b_lo[0]) & (x0 <= b_hi[0])
                near &= y1 >= b_lo[1]
                near &= y0 <= b_hi[1]
                near = np.flatnonzero(near)
            near = self._could_collide(near, c, apart, e0, e1)
            if near.size:
                crossed[near] |= _crossed_concrete([plane], a[near], b[near])
        # concrete circles: a distance test per path, cheap enough for all; the discs every
        # body may hit in one call
        free = [d for d, apart in zip(self.discs, self.disc_apart) if apart is None]
        if free and not self.timed_concrete:
            crossed |= _crossed_concrete([], a, b, free)
        for disc, c, apart in zip(self.discs, self.disc_bodies, self.disc_apart):
            if apart is None and not self.timed_concrete:
                continue
            near = self._could_collide(np.arange(a.shape[0]), c, apart, e0, e1)
            if near.size:
                crossed[near] |= _crossed_concrete([], a[near], b[near], [disc])
        crossed = crossed.reshape(-1, n) & e0 & e1 & self.movable
        self.tunneled |= crossed.any(axis=0)

    def _could_collide(self, paths, c, apart, e0, e1) -> np.ndarray:
        """The paths among `paths` (indices, step * n + body) whose body could collide with
        concrete body `c` in that step: not one of `apart`, and `c` existing at both ends."""
        n = self.model.n_bodies
        if apart is not None:
            paths = paths[~np.isin(paths % n, apart)]
        if self.timed_concrete:
            paths = paths[(e0[:, c] & e1[:, c])[paths // n]]
        return paths

    def values(self) -> dict:
        """{column: value} for the metric columns (see `columns`)."""
        from isaac.engine import diagnostics
        from isaac.engine.records import state_hash

        out: dict = {}
        last = self.last
        for name in self.metrics:
            if name == "final_state":
                out["final_step"] = int(last.step)
                out["final_state_hash"] = state_hash(last)
                w = np.where(np.asarray(last.exists) & self.movable, self.model.mass, 0.0)
                total = float(w.sum())
                pos = np.asarray(last.position)
                out["final_com_x"] = float(w @ pos[:, 0]) / total if total > 0 else None
                out["final_com_y"] = float(w @ pos[:, 1]) / total if total > 0 else None
                names = list(self.model.names)
                for body in self.final_bodies:
                    k = names.index(body) if body in names else None
                    for f, attr, c in _BODY_FIELDS:
                        col = f"final.{body}.{f}"
                        if k is None:
                            out[col] = None
                            continue
                        arr = np.asarray(getattr(last, attr))
                        out[col] = float(arr[k] if c is None else arr[k, c])
            elif name == "max_depth":
                out["max_depth"] = max(self.max_depth, 0.0)
            elif name == "energy_drift":
                e0 = diagnostics.summary(self.model, self.first, self.gravity)
                e1 = diagnostics.summary(self.model, last, self.gravity)
                start = e0.kinetic_energy + e0.potential_energy
                end = e1.kinetic_energy + e1.potential_energy
                out["energy_change"] = end - start
                out["energy_drift"] = (end - start) / abs(start) if start != 0.0 else None
                # isaac.engine.energy_check; a scene with a motor is not checked (False)
                out["energy_rose"] = self.energy.flagged
                out["energy_rose_step"] = self.energy.step
            elif name == "contacts":
                out["contacts"] = self.contacts
                out["contact_steps"] = self.contact_steps
            elif name == "tunneled":
                hit = np.flatnonzero(self.tunneled)
                out["tunneled"] = int(hit.size)
                out["tunneled_bodies"] = ",".join(str(self.model.names[i]) for i in hit)
        return out
