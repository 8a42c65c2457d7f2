"""Optional Foxglove channel: the bodies and contacts as a ``foxglove.SceneUpdate`` per step.

Foxglove recognises its well-known schemas by name; the file carries the descriptor set, built
here with ``descriptor_pb2``: the classic ``foxglove`` messages this channel uses (SceneUpdate,
SceneEntity, LinePrimitive, Pose, Vector3, Quaternion, Point3, Color) with their published field
numbers, less the fields and primitive types ISAAC never writes (those stay wire-compatible:
a reader with the full schema decodes these messages unchanged).

One message per step on ``/foxglove/scene`` (frame ``world``, z = 0, physics y-up):
- entity ``bodies``: every existing body outline as one ``LINE_LIST`` (edge i -> i+1 pairs);
- entity ``contacts``: unit normals at the contact points (``LINE_LIST``, ``normal_length`` m)
  and impulses ``j n`` (``LINE_LIST``, ``impulse_scale`` m per N s).
This is for looking: off by default (it costs more than the physics channels).
"""

from __future__ import annotations

import numpy as np
from google.protobuf import descriptor_pb2, timestamp_pb2

from recorder import schema as S
from recorder.shapes import drawn_shapes

TOPIC = "/foxglove/scene"
SCHEMA_NAME = "foxglove.SceneUpdate"
_F = descriptor_pb2.FieldDescriptorProto

_MESSAGES = {
    "Vector3": [("x", 1, "double"), ("y", 2, "double"), ("z", 3, "double")],
    "Quaternion": [("x", 1, "double"), ("y", 2, "double"), ("z", 3, "double"), ("w", 4, "double")],
    "Point3": [("x", 1, "double"), ("y", 2, "double"), ("z", 3, "double")],
    "Color": [("r", 1, "double"), ("g", 2, "double"), ("b", 3, "double"), ("a", 4, "double")],
    "Pose": [("position", 1, ".foxglove.Vector3"), ("orientation", 2, ".foxglove.Quaternion")],
    "LinePrimitive": [
        ("type", 1, "enum:.foxglove.LinePrimitive.Type"),
        ("pose", 2, ".foxglove.Pose"),
        ("thickness", 3, "double"),
        ("scale_invariant", 4, "bool"),
        ("points", 5, "*.foxglove.Point3"),
        ("color", 6, ".foxglove.Color"),
        ("colors", 7, "*.foxglove.Color"),
        ("indices", 8, "*fixed32"),
    ],
    "SceneEntity": [
        ("timestamp", 1, ".google.protobuf.Timestamp"),
        ("frame_id", 2, "string"),
        ("id", 3, "string"),
        ("frame_locked", 5, "bool"),
        ("lines", 11, "*.foxglove.LinePrimitive"),
    ],
    "SceneUpdate": [("entities", 2, "*.foxglove.SceneEntity")],
}
_SCALAR = {
    "double": _F.TYPE_DOUBLE,
    "bool": _F.TYPE_BOOL,
    "string": _F.TYPE_STRING,
    "fixed32": _F.TYPE_FIXED32,
}


def descriptor_set_bytes() -> bytes:
    """Serialized FileDescriptorSet: google/protobuf/timestamp.proto + the foxglove messages."""
    ts = descriptor_pb2.FileDescriptorProto()
    timestamp_pb2.DESCRIPTOR.CopyToProto(ts)
    fd = descriptor_pb2.FileDescriptorProto(
        name="foxglove/SceneUpdate.proto", package="foxglove", syntax="proto3"
    )
    fd.dependency.append(ts.name)
    for name, fields in _MESSAGES.items():
        m = fd.message_type.add(name=name)
        if name == "LinePrimitive":
            enum = m.enum_type.add(name="Type")
            for i, value in enumerate(("LINE_STRIP", "LINE_LOOP", "LINE_LIST")):
                enum.value.add(name=value, number=i)
        for fname, number, typ in fields:
            f = m.field.add(name=fname, number=number)
            repeated = typ.startswith("*")
            typ = typ.lstrip("*")
            f.label = _F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL
            if typ.startswith("enum:"):
                f.type, f.type_name = _F.TYPE_ENUM, typ[5:]
            elif typ.startswith("."):
                f.type, f.type_name = _F.TYPE_MESSAGE, typ
            else:
                f.type = _SCALAR[typ]
    fds = descriptor_pb2.FileDescriptorSet()
    fds.file.extend([ts, fd])
    return fds.SerializeToString(deterministic=True)


# one Point3 as a length-delimited field 5 of LinePrimitive: tag, length 27, then x, y, z doubles
_POINT = np.dtype(
    [
        ("tag", "u1"),
        ("len", "u1"),
        ("tx", "u1"),
        ("x", "<f8"),
        ("ty", "u1"),
        ("y", "<f8"),
        ("tz", "u1"),
        ("z", "<f8"),
    ]
)
assert _POINT.itemsize == 29


def _points(xy: np.ndarray) -> bytes:
    """Repeated Point3 field (number 5) of (k, 2) points, z = 0, encoded in one numpy pass."""
    out = np.empty(xy.shape[0], dtype=_POINT)
    out["tag"], out["len"] = (5 << 3) | 2, 27
    out["tx"], out["ty"], out["tz"] = 0x09, 0x11, 0x19
    out["x"], out["y"], out["z"] = xy[:, 0], xy[:, 1], 0.0
    return out.tobytes()


def _msg(number: int, *parts: bytes) -> bytes:
    return S.enc_bytes(number, b"".join(parts))


_POSE = _msg(
    2,
    _msg(1, S.enc_double(1, 0.0), S.enc_double(2, 0.0), S.enc_double(3, 0.0)),
    _msg(2, S.enc_double(1, 0.0), S.enc_double(2, 0.0), S.enc_double(3, 0.0), S.enc_double(4, 1.0)),
)


def _color(rgba) -> bytes:
    return _msg(6, *(S.enc_double(i + 1, float(c)) for i, c in enumerate(rgba)))


def _line_list(segments: np.ndarray, rgba, thickness: float) -> bytes:
    """A LINE_LIST LinePrimitive (field 11 of SceneEntity) from (k, 2, 2) segments."""
    return _msg(
        11,
        S.enc_uint(1, 2),
        _POSE,
        S.enc_double(3, thickness),
        S.enc_uint(4, 1),
        _points(segments.reshape(-1, 2)),
        _color(rgba),
    )


def _entity(t_ns: int, entity_id: str, *lines: bytes) -> bytes:
    stamp = _msg(1, S.enc_uint(1, t_ns // 1_000_000_000), S.enc_uint(2, t_ns % 1_000_000_000))
    return _msg(2, stamp, S.enc_string(2, "world"), S.enc_string(3, entity_id), *lines)


class SceneEncoder:
    """Builds the per-step ``foxglove.SceneUpdate`` bytes from a StepRecord.

    model: names, vertices_local (n, V, 2), vertex_count (the Simulation model or a WorldTable).
    """

    def __init__(self, model, *, impulse_scale: float, normal_length: float) -> None:
        local, counts = drawn_shapes(model)  # circles as a ring with a spoke
        body, start = [], []
        for k, c in enumerate(counts):
            body.extend([k] * int(c))
            start.extend(range(int(c)))
        self.body = np.array(body, dtype=np.int64)
        vi = np.array(start, dtype=np.int64)
        nxt = np.where(vi + 1 < counts[self.body], vi + 1, 0)
        # every edge (i -> i+1) of every body, in the body frame
        self.edge_from = local[self.body, vi]
        self.edge_to = local[self.body, nxt]
        self.impulse_scale = impulse_scale
        self.normal_length = normal_length

    def encode(self, record, t_ns: int) -> bytes:
        angle = record.angle[self.body]
        c, s = np.cos(angle), np.sin(angle)
        pos = record.position[self.body]
        keep = record.exists[self.body]
        seg = np.empty((self.body.size, 2, 2))
        for j, pts in enumerate((self.edge_from, self.edge_to)):
            seg[:, j, 0] = pos[:, 0] + c * pts[:, 0] - s * pts[:, 1]
            seg[:, j, 1] = pos[:, 1] + s * pts[:, 0] + c * pts[:, 1]
        bodies = _entity(t_ns, "bodies", _line_list(seg[keep], (0.3, 0.55, 0.9, 1.0), 2.0))
        con = record.contacts
        p, n = con.point, con.normal
        normals = np.stack([p, p + n * self.normal_length], axis=1)
        impulses = np.stack([p, p + n * (con.impulse * self.impulse_scale)[:, None]], axis=1)
        contacts = _entity(
            t_ns,
            "contacts",
            _line_list(normals, (0.95, 0.8, 0.15, 1.0), 2.0),
            _line_list(impulses, (0.85, 0.25, 0.85, 1.0), 3.0),
        )
        return bodies + contacts
