"""Where two payloads of one topic differ: the field, the body or contact row, both values and
their distance in ULPs (`locate`), for a replay or a diff whose bytes did not match."""

from __future__ import annotations

import struct
from collections.abc import Callable

import numpy as np

from recorder import schema as S
from recorder.reader import (
    DECODE_ERRORS,
    WorldTable,
    check_bodies,
    contacts_from_message,
    joints_from_message,
)
from replay.report import Divergence

# per-row 2-vector fields, flattened x0, y0, x1, y1 ... in the log
_VECTOR_FIELDS = {"position", "velocity", "point", "normal", "push_a", "push_b"}
_CONTACT_KEY = ("substep", "a", "b", "slot")


# ---------------------------------------------------------------------------------------------
# ULP distance

_INT64_MIN = -(1 << 63)


def _ordered(bits: int) -> int:
    """Map float64 bits (as a signed int64) onto a line where adjacent floats differ by 1.

    Positive floats keep their bits; negative floats (sign bit set, so a negative int64) are
    reflected: -0.0 maps to 0 like +0.0, the smallest negative subnormal to -1, and so on.
    """
    return bits if bits >= 0 else _INT64_MIN - bits


def ulp_distance(a: float, b: float) -> int | None:
    """Number of float64 values between ``a`` and ``b`` (0 when equal; None if either is NaN).

    Computed on the int64 view of the two doubles, sign handled by reflecting negatives, so
    e.g. ``ulp_distance(x, np.nextafter(x, inf)) == 1`` and ``ulp_distance(-0.0, 0.0) == 0``.
    """
    if a != a or b != b:
        return None
    ia = struct.unpack("<q", struct.pack("<d", a))[0]
    ib = struct.unpack("<q", struct.pack("<d", b))[0]
    return abs(_ordered(ia) - _ordered(ib))


def ulp_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Element-wise `ulp_distance` of two float64 arrays, as uint64 (NaN pairs give 0)."""
    ia = np.ascontiguousarray(a, dtype="<f8").view(np.int64)
    ib = np.ascontiguousarray(b, dtype="<f8").view(np.int64)
    oa = np.where(ia >= 0, ia, np.int64(_INT64_MIN) - ia)
    ob = np.where(ib >= 0, ib, np.int64(_INT64_MIN) - ib)
    # the difference of two int64 fits in a uint64: subtract in wrapping arithmetic, larger first
    with np.errstate(over="ignore"):
        d = np.where(oa >= ob, (oa - ob).view(np.uint64), (ob - oa).view(np.uint64))
    nan = np.isnan(a) | np.isnan(b)
    return np.where(nan, np.uint64(0), d)


# ---------------------------------------------------------------------------------------------
# locating a difference inside two decoded messages


class MalformedMessage(ValueError):
    """A payload that does not decode, or whose arrays do not fit together (a damaged log, not
    a divergence). ``side``: 0 for the logged payload (log A), 1 for the other."""

    def __init__(self, side: int, why: str) -> None:
        self.side = side
        super().__init__(why)


def _decoded(message: str, topic: str, payload: bytes, side: int, n_bodies: int) -> dict:
    """``payload`` decoded, its arrays checked against each other and a contact's bodies
    against the scene's ``n_bodies`` (MalformedMessage if not)."""
    try:
        d = S.decode(message, payload)
        if topic == "/bodies":
            check_bodies(d)
        elif topic == "/world":
            WorldTable.from_message(d)
        elif topic == "/joints":
            joints_from_message(d)
        elif topic == "/contacts":
            contacts_from_message(d)
            for side_name, idx in (("a", d["a"]), ("b", d["b"])):
                if idx.size and int(idx.max()) >= n_bodies:
                    row = int(np.flatnonzero(idx >= n_bodies)[0])
                    raise ValueError(
                        f"/contacts: row {row} names body {int(idx[row])} as {side_name}; "
                        f"the scene has {n_bodies} bodies"
                    )
    except DECODE_ERRORS as exc:
        raise MalformedMessage(side, f"is malformed ({exc})") from None
    return d


def _float_mismatch(la: np.ndarray, ra: np.ndarray, tolerance: float | None) -> np.ndarray:
    """Mask of elements that differ: any bit (bitwise), or beyond tolerance."""
    if tolerance is None:
        return np.ascontiguousarray(la, dtype="<f8").view(np.uint64) != np.ascontiguousarray(
            ra, dtype="<f8"
        ).view(np.uint64)
    with np.errstate(invalid="ignore", over="ignore"):
        close = np.abs(la - ra) <= tolerance + tolerance * np.abs(la)
    same_nan = np.isnan(la) & np.isnan(ra)
    return ~(close | same_nan)


class _Finder:
    """Collects the differences of one channel at one step; keeps the first, counts the rest."""

    def __init__(self, step: int, channel: str, tolerance: float | None) -> None:
        self.step = step
        self.channel = channel
        self.tolerance = tolerance
        self.first: Divergence | None = None
        self.count = 0
        self.max_ulps: int | None = None
        self.bit_differences = 0  # values whose bits differ (within tolerance or not)

    def note_ulps(self, ulps: np.ndarray) -> None:
        if ulps.size:
            m = int(ulps.max())
            self.max_ulps = m if self.max_ulps is None else max(self.max_ulps, m)

    def array(self, name: str, la, ra, *, is_float: bool, where: Callable[[int], dict]) -> None:
        la = np.atleast_1d(np.asarray(la))
        ra = np.atleast_1d(np.asarray(ra))
        if la.shape != ra.shape:
            self._add(
                Divergence(
                    self.step,
                    self.channel,
                    "count",
                    field=name,
                    logged=int(la.size),
                    replayed=int(ra.size),
                ),
                1,
            )
            return
        if is_float:
            la = la.astype(np.float64, copy=False)
            ra = ra.astype(np.float64, copy=False)
            bits = la.view(np.uint64) != ra.view(np.uint64)
            n_bits = int(np.count_nonzero(bits))
            if not n_bits:
                return
            self.bit_differences += n_bits
            ulps = ulp_distances(la[bits], ra[bits])
            self.note_ulps(ulps)
            bad = _float_mismatch(la, ra, self.tolerance) if self.tolerance is not None else bits
        else:
            bad = la != ra
            self.bit_differences += int(np.count_nonzero(bad))
        idx = np.flatnonzero(bad)
        if not idx.size:
            return
        i = int(idx[0])
        lv, rv = la[i].item(), ra[i].item()
        label = name
        if name in _VECTOR_FIELDS:
            label = f"{name}.{'xy'[i % 2]}"
            i //= 2
        d = Divergence(
            self.step,
            self.channel,
            "value",
            field=label,
            logged=lv,
            replayed=rv,
            ulps=ulp_distance(lv, rv) if is_float else None,
            **where(i),
        )
        self._add(d, int(idx.size))

    def scalar(self, name: str, lv, rv, *, is_float: bool) -> None:
        if is_float:
            self.array(name, lv, rv, is_float=True, where=lambda i: {})
        elif lv != rv:
            if name == "state_hash" and self.tolerance is not None:
                return  # a hash cannot be close: in tolerance mode it is not compared
            self.bit_differences += 1
            self._add(
                Divergence(self.step, self.channel, "value", field=name, logged=lv, replayed=rv), 1
            )

    def _add(self, d: Divergence, n: int) -> None:
        self.count += n
        if self.first is None:
            self.first = d

    def result(self) -> Divergence | None:
        if self.first is not None:
            self.first.differing_values = self.count
            self.first.max_ulps = self.max_ulps
        return self.first


# the fields compared, per row (a manifold's fields on each of its rows), in format 2's message
# order: (record field, name in a format 2 log, name in a format 1 log; None: not in it)
_CONTACT_COMPARED = (
    ("substep", "substep", "substep"),
    ("a", "a", "a"),
    ("b", "b", "b"),
    ("feature", "feature", "feature"),
    ("points", "points", None),
    ("slot", None, "slot"),
    ("normal", "normal", "normal"),
    ("pair_depth", "pair_depth", None),
    ("push_a", "push_a", "push_a"),
    ("push_b", "push_b", "push_b"),
    ("point", "point", "point"),
    ("depth", "point_depth", "depth"),
    ("impulse", "impulse", "impulse"),
    ("tangent_impulse", "tangent_impulse", "tangent_impulse"),
    ("restitution", "restitution", "restitution"),
)


def _row_values(c, name: str) -> np.ndarray:
    """A Contacts field as compared, flattened; ``points``: each row's manifold's size."""
    if name == "points":
        starts = np.flatnonzero(np.asarray(c.slot) == 0)
        counts = np.diff(np.append(starts, len(c)))
        return np.repeat(counts, counts)
    return np.ravel(getattr(c, name))


def _locate_contacts(f: _Finder, step: int, dl: dict, dr: dict, names: list):
    """The /contacts branch of `locate`: both messages (of either format) as rows, compared
    field by field (a manifold's field on each of its rows: a change shows at the manifold's
    first row). Returns a count Divergence, or None after filling ``f``."""
    cl, cr = contacts_from_message(dl), contacts_from_message(dr)
    v1 = "slot" in dl or "slot" in dr  # a format 1 log on one side: its fields only
    ml, mr = len(cl), len(cr)
    manifold_l = np.cumsum(np.asarray(cl.slot) == 0) - 1

    def row(i: int) -> dict:
        c = {"row": i}
        for k in _CONTACT_KEY:
            v = getattr(cl, k)
            c[k] = int(v[i]) if i < v.size else None
        if "slot" not in dl and i < ml:
            c["manifold"] = int(manifold_l[i])
        for side in ("a", "b"):
            j = c[side]
            if j is not None and 0 <= j < len(names):
                c[f"{side}_name"] = str(names[j])
        return {"contact": c}

    if ml != mr:
        # the first row whose identity (sub-step, a, b, slot) differs says where it starts
        m = min(ml, mr)
        keys_l = np.stack([getattr(cl, k)[:m].astype(np.int64) for k in _CONTACT_KEY])
        keys_r = np.stack([getattr(cr, k)[:m].astype(np.int64) for k in _CONTACT_KEY])
        off = np.flatnonzero((keys_l != keys_r).any(axis=0))
        i = int(off[0]) if off.size else m
        where = row(i)["contact"] if i < ml else None
        detail = f"the rows agree up to row {i - 1}" if i > 0 else "row 0 already differs"
        if where is not None:
            detail += (
                f"; logged row {i} is {where.get('a_name', where['a'])!r}-"
                f"{where.get('b_name', where['b'])!r} slot {where['slot']}"
            )
        return Divergence(
            step,
            "/contacts",
            "count",
            field="contacts",
            logged=ml,
            replayed=mr,
            contact=where,
            detail=detail,
        )
    f.scalar("step", dl["step"], dr["step"], is_float=False)
    f.scalar("time", dl["time"], dr["time"], is_float=True)
    for name, v2_name, v1_name in _CONTACT_COMPARED:
        label = v1_name if v1 else v2_name
        if label is None:
            continue
        lv, rv = _row_values(cl, name), _row_values(cr, name)
        f.array(label, lv, rv, is_float=lv.dtype.kind == "f", where=row)
    return None


def check_payload(topic: str, payload: bytes, n_bodies: int) -> None:
    """MalformedMessage unless ``payload`` decodes as ``topic`` with arrays that fit together
    (for payloads equal on both sides of a diff, which `locate` never sees)."""
    _decoded(S.TOPICS[topic], topic, payload, 0, n_bodies)


# per-joint values of each /joints field (2-vectors and the solver's impulse columns)
_JOINT_WIDTH = {
    "anchor_a": 2,
    "anchor_b": 2,
    "linear_impulse": 2,
    "error": 2,
    "impulses": 6,
}


def _locate_joints(f: _Finder, step: int, dl: dict, dr: dict, joint_names) -> Divergence | None:
    """The first difference of two /joints messages: the joint (index, name), the field and,
    for a field of several values per joint, which (x / y, or the impulse column)."""
    ml, mr = dl["angular_impulse"].size, dr["angular_impulse"].size
    if ml != mr:
        return Divergence(step, "/joints", "count", field="joints", logged=ml, replayed=mr)
    f.scalar("step", dl["step"], dr["step"], is_float=False)
    f.scalar("time", dl["time"], dr["time"], is_float=True)

    def joint(i: int, w: int) -> dict:
        k = i // w
        name = str(joint_names[k]) if joint_names is not None and k < len(joint_names) else None
        out = {"index": k, "name": name}
        if w == 2:
            out["component"] = "xy"[i % 2]
        elif w > 2:
            out["component"] = f"J{i % w}"
        return {"joint": out}

    for name, _num, _typ, _repeated in S.spec("Joints")[2:]:
        w = _JOINT_WIDTH.get(name, 1)
        f.array(name, dl[name], dr[name], is_float=True, where=lambda i, w=w: joint(i, w))
    return None


def locate(
    topic: str,
    step: int,
    logged: bytes,
    replayed: bytes,
    names: list,
    tolerance: float | None = None,
    joint_names: list | None = None,
) -> tuple[Divergence | None, int | None]:
    """Decode two payloads of ``topic`` that differ in bytes and find where.

    Returns (the first difference beyond the tolerance or None, the largest ULP distance seen).
    Fields are visited in message order; within a field the lowest body / row index comes first.
    Raises MalformedMessage if either payload does not decode or its arrays do not fit together.
    """
    message = S.TOPICS[topic]
    dl = _decoded(message, topic, logged, 0, len(names))
    dr = _decoded(message, topic, replayed, 1, len(names))
    f = _Finder(step, topic, tolerance)

    def body(i: int) -> dict:
        return {"body": i, "body_name": str(names[i]) if 0 <= i < len(names) else None}

    spec = S.spec(message)
    if topic == "/bodies":
        nl, nr = dl["angle"].size, dr["angle"].size
        if nl != nr:
            return Divergence(step, topic, "count", field="bodies", logged=nl, replayed=nr), None
        for name, _num, typ, repeated in spec:
            if repeated:
                f.array(name, dl[name], dr[name], is_float=typ == "double", where=body)
            else:
                f.scalar(name, dl[name], dr[name], is_float=typ == "double")
    elif topic == "/contacts":
        d = _locate_contacts(f, step, dl, dr, names)
        if d is not None:
            return d, None
    elif topic == "/stats":
        for name, _num, typ, _repeated in spec:
            f.scalar(name, dl[name], dr[name], is_float=typ == "double")
    elif topic == "/joints":
        d = _locate_joints(f, step, dl, dr, joint_names)
        if d is not None:
            return d, None
    else:  # /world
        f.scalar("step", dl["step"], dr["step"], is_float=False)
        f.scalar("time", dl["time"], dr["time"], is_float=True)
        bl, br = dl["bodies"], dr["bodies"]
        if len(bl) != len(br):
            return Divergence(
                step, topic, "count", field="bodies", logged=len(bl), replayed=len(br)
            ), None
        for i, (a, b) in enumerate(zip(bl, br)):
            for name, _num, typ, repeated in S.MESSAGES["Body"]:
                if repeated:
                    f.array(name, a[name], b[name], is_float=True, where=lambda _j, i=i: body(i))
                elif a[name] != b[name] or (
                    typ == "double" and ulp_distance(a[name], b[name]) != 0
                ):
                    if typ == "double":
                        f.array(
                            name, a[name], b[name], is_float=True, where=lambda _j, i=i: body(i)
                        )
                    else:
                        f.bit_differences += 1
                        f._add(
                            Divergence(
                                step,
                                topic,
                                "value",
                                field=name,
                                logged=a[name],
                                replayed=b[name],
                                **body(i),
                            ),
                            1,
                        )
        jl, jr = dl.get("joints", []), dr.get("joints", [])
        if len(jl) != len(jr):
            return Divergence(
                step, topic, "count", field="joints", logged=len(jl), replayed=len(jr)
            ), None
        for k, (a, b) in enumerate(zip(jl, jr)):
            where = lambda _j, k=k, a=a: {"joint": {"index": k, "name": a["name"]}}  # noqa: E731
            for name, _num, typ, _repeated in S.spec("Joint"):
                if typ == "double":
                    f.array(f"joints.{name}", a[name], b[name], is_float=True, where=where)
                elif a[name] != b[name]:
                    f.bit_differences += 1
                    f._add(
                        Divergence(
                            step,
                            topic,
                            "value",
                            field=f"joints.{name}",
                            logged=a[name],
                            replayed=b[name],
                            **where(0),
                        ),
                        1,
                    )
    return f.result(), f.max_ulps


# ---------------------------------------------------------------------------------------------
# checks on the log's header
