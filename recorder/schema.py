"""The ISAAC log schema (protobuf, proto3) and a hand-written wire encoder/decoder for it.

The schema is built at run time with ``descriptor_pb2`` (no protoc) and stored in every MCAP file
as a serialized ``FileDescriptorSet``, so any generic MCAP + protobuf reader decodes the log with
no code from this project (docs/log-format.md is the public description).

Why a hand-written encoder: the hot messages are struct-of-arrays. A packed ``repeated double`` is
``tag, byte length, raw little-endian float64``, so it is written straight from a numpy array with
``tobytes()`` (all 64 bits kept, no per-element Python work). Body indices are ``fixed32`` for the
same reason (raw little-endian uint32) and booleans are one byte each. Scalar fields are always
written, even when zero, so ``-0.0`` keeps its sign bit and the payload never depends on values.
Tests decode the bytes with google.protobuf's message factory built from the stored descriptor set,
never with this module.

Layout of arrays: a per-body 2-vector field (``position``, ``velocity``) is flattened as
``x0, y0, x1, y1, ...``; so are per-contact 2-vectors (``point``, ``normal``, ``push_a``,
``push_b``) and a body's ``vertices_local``.
"""

from __future__ import annotations

import functools
import struct

import numpy as np
from google.protobuf import descriptor_pb2

PACKAGE = "isaac.log"
FILE_NAME = "isaac/log.proto"
SCHEMA_ENCODING = "protobuf"
MESSAGE_ENCODING = "protobuf"

_F = descriptor_pb2.FieldDescriptorProto
_TYPE = {
    "double": _F.TYPE_DOUBLE,
    "uint64": _F.TYPE_UINT64,
    "uint32": _F.TYPE_UINT32,
    "fixed32": _F.TYPE_FIXED32,
    "bool": _F.TYPE_BOOL,
    "string": _F.TYPE_STRING,
}

# (name, number, type, repeated, comment) per message; "message:Body" is a nested message type.
# Field numbers are part of the public contract: never renumber, only add.
MESSAGES: dict[str, list[tuple[str, int, str, bool]]] = {
    "Body": [
        ("index", 1, "uint32", False),
        ("name", 2, "string", False),
        ("vertices_local", 3, "double", True),  # x0, y0, x1, y1 ... (m, body frame, about the CoM)
        ("mass", 4, "double", False),  # kg (area * density, also for concrete bodies)
        ("inertia", 5, "double", False),  # kg m^2 about the centre of mass
        ("restitution", 6, "double", False),
        ("concrete", 7, "bool", False),  # immovable (infinite mass and inertia)
        ("exists", 8, "bool", False),  # whether it is in the scene at this step
        ("friction", 9, "double", False),  # Coulomb coefficient
        # a circle's radius (m; its vertices_local is its centre, one vertex); absent: a polygon
        ("circle_radius", 10, "double", False),
    ],
    "World": [
        ("step", 1, "uint64", False),
        ("time", 2, "double", False),  # s
        ("bodies", 3, "message:Body", True),  # in body-index order
    ],
    "Bodies": [
        ("step", 1, "uint64", False),
        ("time", 2, "double", False),  # s, step * dt
        ("position", 3, "double", True),  # (n, 2) flattened, m, world
        ("angle", 4, "double", True),  # (n,) rad, counter-clockwise
        ("velocity", 5, "double", True),  # (n, 2) flattened, m/s, world
        ("angular_velocity", 6, "double", True),  # (n,) rad/s
        ("exists", 7, "bool", True),  # (n,)
    ],
    # format 2 (per manifold): a manifold is one pair's contact during one sub-step, its points
    # follow one another in the point arrays (``points`` of them); numbers 3-7, 9, 11 and 12
    # held format 1's per-row copies of the pair fields and are never used again
    "Contacts": [
        ("step", 1, "uint64", False),
        ("time", 2, "double", False),
        ("substep", 16, "fixed32", True),  # (k,) per manifold
        ("a", 17, "fixed32", True),  # (k,) body index, a < b
        ("b", 18, "fixed32", True),  # (k,)
        ("feature", 19, "fixed32", True),  # (k,)
        ("points", 20, "fixed32", True),  # (k,) points of the manifold (1 or 2)
        ("normal", 21, "double", True),  # (k, 2) flattened, unit, from a to b
        ("pair_depth", 22, "double", True),  # (k,) m, the pair's MTD depth
        ("pushed", 25, "fixed32", True),  # (p,) ascending: the manifolds the push-out moved
        ("push_a", 23, "double", True),  # (p, 2) flattened, m, world: of those manifolds
        ("push_b", 24, "double", True),  # (p, 2) flattened, m, world
        ("point", 8, "double", True),  # (m, 2) flattened, m, world; per point from here on
        ("point_depth", 10, "double", True),  # (m,) m, the point's own penetration
        ("impulse", 13, "double", True),  # (m,) N s, >= 0
        ("tangent_impulse", 14, "double", True),  # (m,) N s, signed along (-n_y, n_x)
        ("restitution", 15, "double", True),  # (m,)
    ],
    "Stats": [
        ("step", 1, "uint64", False),
        ("time", 2, "double", False),
        ("kinetic_energy", 3, "double", False),  # J
        ("potential_energy", 4, "double", False),  # J, relative to the world origin
        ("total_energy", 5, "double", False),  # J
        ("linear_momentum_x", 6, "double", False),  # kg m/s
        ("linear_momentum_y", 7, "double", False),  # kg m/s
        ("angular_momentum", 8, "double", False),  # kg m^2/s about the origin
        ("contact_count", 9, "uint32", False),
        ("max_depth", 10, "double", False),  # m (0 with no contact)
        ("max_impulse", 11, "double", False),  # N s (0 with no contact)
        ("state_hash", 12, "string", False),  # isaac.engine.diagnostics.state_hash, sha256 hex
    ],
}

# The joint messages (a scene with joints only): ``World.joints`` (field 4) holds the joint
# table and ``/joints`` a step's joint rows. A scene without joints stores the schema above
# alone, so its log keeps the bytes it had before joints existed.
WORLD_JOINTS_FIELD = ("joints", 4, "message:Joint", True)  # in joint-index order
JOINT_MESSAGES: dict[str, list[tuple[str, int, str, bool]]] = {
    "Joint": [
        ("index", 1, "uint32", False),
        ("name", 2, "string", False),
        ("type", 3, "string", False),  # revolute, distance, weld or prismatic
        ("a", 4, "uint32", False),  # body index
        ("b", 5, "uint32", False),  # body index
        ("local_a", 6, "double", True),  # (2,) m, a's frame (about a's centre of mass)
        ("local_b", 7, "double", True),  # (2,) m, b's frame
        ("axis", 8, "double", True),  # (2,) unit, a's frame (prismatic; (1, 0) otherwise)
        ("reference_angle", 9, "double", False),  # rad, angle of b less angle of a at rest
        ("length", 10, "double", False),  # m (distance: rest length)
        ("min_length", 11, "double", False),  # m (distance; -inf: none)
        ("max_length", 12, "double", False),  # m (distance; +inf: none)
        ("stiffness", 13, "double", False),  # Hz (0 when spring is false)
        ("damping_ratio", 14, "double", False),
        ("lower", 15, "double", False),  # rad or m (revolute, prismatic; -inf: none)
        ("upper", 16, "double", False),  # rad or m (+inf: none)
        ("motor_speed", 17, "double", False),  # rad/s or m/s (0 when motor is false)
        ("max_motor", 18, "double", False),  # N m or N
        ("spring", 19, "bool", False),  # stiffness given (distance, weld)
        ("motor", 20, "bool", False),  # motor_speed given (revolute, prismatic)
        ("collide_connected", 21, "bool", False),
    ],
    "Joints": [
        ("step", 1, "uint64", False),
        ("time", 2, "double", False),  # s
        ("anchor_a", 3, "double", True),  # (m, 2) m, world
        ("anchor_b", 4, "double", True),  # (m, 2) m, world
        ("linear_impulse", 5, "double", True),  # (m, 2) N s, world, on b
        ("angular_impulse", 6, "double", True),  # (m,) N m s, on b
        ("motor_impulse", 7, "double", True),  # (m,) N m s or N s, on b
        ("limit_impulse", 8, "double", True),  # (m,) lower less upper, on b
        ("error", 9, "double", True),  # (m, 2) m and rad left after the position correction
        ("impulses", 10, "double", True),  # (m, 6) the solver's accumulated impulses J0 .. JU
    ],
}

# Format 1's Contacts (one row per contact point, every field per row), read from older logs
# only: never written, and not in the schema stored in new logs.
LEGACY_MESSAGES = {
    "ContactsV1": [
        ("step", 1, "uint64", False),
        ("time", 2, "double", False),
        ("substep", 3, "fixed32", True),
        ("a", 4, "fixed32", True),
        ("b", 5, "fixed32", True),
        ("feature", 6, "fixed32", True),
        ("slot", 7, "fixed32", True),
        ("point", 8, "double", True),  # (m, 2) flattened, m, world
        ("normal", 9, "double", True),  # (m, 2) flattened, unit, from a to b
        ("depth", 10, "double", True),  # (m,) m
        ("push_a", 11, "double", True),  # (m, 2) flattened, m, world
        ("push_b", 12, "double", True),  # (m, 2) flattened, m, world
        ("impulse", 13, "double", True),  # (m,) N s, >= 0
        ("tangent_impulse", 14, "double", True),  # (m,) N s, signed along (-n_y, n_x)
        ("restitution", 15, "double", True),  # (m,)
    ],
}
# the field numbers only format 1 uses (a format 1 message holding a contact has some of them)
CONTACTS_V1_ONLY = frozenset((3, 4, 5, 6, 7, 9, 11, 12))

# topic -> message name (without package); /joints only in a scene with joints
TOPICS = {
    "/world": "World",
    "/bodies": "Bodies",
    "/contacts": "Contacts",
    "/joints": "Joints",
    "/stats": "Stats",
}
JOINT_TOPICS = frozenset(("/joints",))


def full_name(message: str) -> str:
    """``isaac.log.<message>``: the schema name stored in the MCAP file."""
    return f"{PACKAGE}.{message}"


def _messages(joints: bool) -> dict[str, list[tuple[str, int, str, bool]]]:
    if not joints:
        return MESSAGES
    out = {**MESSAGES, **JOINT_MESSAGES}
    out["World"] = [*MESSAGES["World"], WORLD_JOINTS_FIELD]
    return out


def file_descriptor_set(joints: bool = False) -> descriptor_pb2.FileDescriptorSet:
    """The FileDescriptorSet holding every ISAAC log message (one .proto file, proto3); with
    ``joints``, also ``Joint``, ``Joints`` and ``World.joints`` (a scene with joints)."""
    fdp = descriptor_pb2.FileDescriptorProto(name=FILE_NAME, package=PACKAGE, syntax="proto3")
    for message, fields in _messages(joints).items():
        mdp = fdp.message_type.add(name=message)
        for name, number, typ, repeated in fields:
            f = mdp.field.add(name=name, number=number, json_name=_json_name(name))
            f.label = _F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL
            if typ.startswith("message:"):
                f.type = _F.TYPE_MESSAGE
                f.type_name = f".{PACKAGE}.{typ.split(':', 1)[1]}"
            else:
                f.type = _TYPE[typ]
    fds = descriptor_pb2.FileDescriptorSet()
    fds.file.append(fdp)
    return fds


@functools.cache
def schema_bytes(joints: bool = False) -> bytes:
    """The serialized FileDescriptorSet (deterministic bytes) stored as every channel's schema
    (``joints``: the one of a scene with joints)."""
    return file_descriptor_set(joints).SerializeToString(deterministic=True)


def _json_name(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(part.capitalize() for part in rest)


# ---------------------------------------------------------------------------------------------
# encoding: protobuf wire format written by hand (see the module docstring)

_WT_VARINT, _WT_I64, _WT_LEN, _WT_I32 = 0, 1, 2, 5
_pack_d = struct.Struct("<d").pack


def varint(value: int) -> bytes:
    """Protobuf base-128 varint of a non-negative integer."""
    if value < 0x80:
        return _SMALL[value]
    out = bytearray()
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


_SMALL = [bytes((i,)) for i in range(0x80)]


def _tag(number: int, wire_type: int) -> bytes:
    return varint((number << 3) | wire_type)


# tags of fields 1..31 precomputed per wire type (every field number here is below 16)
_TAG_VARINT = [_tag(i, _WT_VARINT) for i in range(32)]
_TAG_I64 = [_tag(i, _WT_I64) for i in range(32)]
_TAG_LEN = [_tag(i, _WT_LEN) for i in range(32)]


def enc_uint(number: int, value: int) -> bytes:
    """A varint scalar field (uint32/uint64/bool), written even when 0."""
    return _TAG_VARINT[number] + varint(int(value))


def enc_double(number: int, value: float) -> bytes:
    """A double scalar field: 8 raw little-endian bytes, written even when 0."""
    return _TAG_I64[number] + _pack_d(value)


def enc_bytes(number: int, data: bytes) -> bytes:
    """A length-delimited field (string, bytes, nested message or packed array)."""
    return b"".join((_TAG_LEN[number], varint(len(data)), data))


def enc_string(number: int, text: str) -> bytes:
    return enc_bytes(number, text.encode("utf-8"))


def enc_doubles(number: int, array: np.ndarray) -> bytes:
    """A packed repeated double: raw little-endian float64 (omitted when empty)."""
    if array.size == 0:
        return b""
    return enc_bytes(number, np.ascontiguousarray(array, dtype="<f8").tobytes())


def enc_fixed32s(number: int, array: np.ndarray) -> bytes:
    """A packed repeated fixed32: raw little-endian uint32 (omitted when empty)."""
    if array.size == 0:
        return b""
    return enc_bytes(number, np.ascontiguousarray(array, dtype="<u4").tobytes())


def enc_bools(number: int, array: np.ndarray) -> bytes:
    """A packed repeated bool: one byte 0/1 each (omitted when empty)."""
    if array.size == 0:
        return b""
    return enc_bytes(number, np.ascontiguousarray(array, dtype=np.uint8).tobytes())


def packed(parts: list, number: int, array: np.ndarray, dtype) -> None:
    """Append a packed repeated field to ``parts`` without copying the array's bytes.

    ``dtype`` is "<f8" (double), "<u4" (fixed32) or np.uint8 (bool); an empty array adds
    nothing. ``b"".join(parts)`` then copies each array once, straight into the message.
    """
    if array.size == 0:
        return
    if array.dtype == np.bool_:
        data = np.ascontiguousarray(array).view(np.uint8)
    elif dtype == "<u4" and array.dtype == np.dtype("<i4"):
        data = np.ascontiguousarray(array).view("<u4")  # same bits (values are >= 0)
    else:
        data = np.ascontiguousarray(array, dtype=dtype)
    parts.append(_TAG_LEN[number])
    parts.append(varint(data.nbytes))
    parts.append(data)


# ---------------------------------------------------------------------------------------------
# decoding: a small wire-format parser driven by MESSAGES (fast path for the reader)


class WireError(ValueError):
    """The bytes are not a valid message of the expected type."""


def _read_varint(buf: bytes, pos: int) -> tuple[int, int]:
    result = 0
    shift = 0
    while True:
        if pos >= len(buf):
            raise WireError("truncated varint")
        byte = buf[pos]
        pos += 1
        result |= (byte & 0x7F) << shift
        if byte < 0x80:
            return result, pos
        shift += 7
        if shift > 63:
            raise WireError("varint too long")


_SPECS = {**_messages(True), **LEGACY_MESSAGES}


def spec(message: str) -> list[tuple[str, int, str, bool]]:
    """(name, number, type, repeated) of every field of ``isaac.log.<message>`` (the joint
    messages and ``World.joints`` included)."""
    return _SPECS[message]


_FIELDS_BY_NUMBER = {
    message: {number: (name, typ, repeated) for name, number, typ, repeated in fields}
    for message, fields in _SPECS.items()
}


def contacts_format(buf: bytes) -> int:
    """1 when ``buf``, a Contacts message, is in format 1 (it holds a field only format 1 uses),
    else 2. A message without contacts reads the same in both. WireError if it does not
    parse."""
    pos, end = 0, len(buf)
    while pos < end:
        key, pos = _read_varint(buf, pos)
        number, wt = key >> 3, key & 7
        if number in CONTACTS_V1_ONLY:
            return 1
        if wt == _WT_VARINT:
            _, pos = _read_varint(buf, pos)
        elif wt == _WT_I64:
            pos += 8
        elif wt == _WT_I32:
            pos += 4
        elif wt == _WT_LEN:
            length, pos = _read_varint(buf, pos)
            pos += length
        else:
            raise WireError(f"unsupported wire type {wt}")
    return 2


_NUMPY = {"double": "<f8", "fixed32": "<u4"}


def decode(message: str, buf: bytes) -> dict:
    """Decode ``buf`` as ``isaac.log.<message>`` into a dict of Python scalars / numpy arrays.

    Repeated numeric fields come back as numpy arrays (float64, uint32 or bool), empty when absent;
    a repeated nested message as a list of dicts. Accepts packed and unpacked encodings.
    ``Contacts`` reads both formats: a format 1 message is decoded as ``ContactsV1`` (its dict
    then has ``slot`` and ``depth``; a format 2 one has ``points`` and ``point_depth``).
    """
    if message == "Contacts" and contacts_format(buf) == 1:
        message = "ContactsV1"
    spec = _FIELDS_BY_NUMBER[message]
    parts: dict[str, list] = {}
    out: dict = {}
    pos, end = 0, len(buf)
    while pos < end:
        key, pos = _read_varint(buf, pos)
        number, wt = key >> 3, key & 7
        field = spec.get(number)
        if wt == _WT_VARINT:
            value, pos = _read_varint(buf, pos)
            raw = ("v", value)
        elif wt == _WT_I64:
            if pos + 8 > end:
                raise WireError("truncated fixed64")
            raw = ("8", buf[pos : pos + 8])
            pos += 8
        elif wt == _WT_I32:
            if pos + 4 > end:
                raise WireError("truncated fixed32")
            raw = ("4", buf[pos : pos + 4])
            pos += 4
        elif wt == _WT_LEN:
            length, pos = _read_varint(buf, pos)
            if pos + length > end:
                raise WireError("truncated length-delimited field")
            raw = ("L", buf[pos : pos + length])
            pos += length
        else:
            raise WireError(f"unsupported wire type {wt}")
        if field is None:
            continue  # unknown field: forward compatible
        name, typ, repeated = field
        kind, data = raw
        if typ.startswith("message:"):
            if kind != "L":
                raise WireError(f"{message}.{name}: expected a nested message")
            value = decode(typ.split(":", 1)[1], data)
        elif typ == "string":
            if kind != "L":
                raise WireError(f"{message}.{name}: expected a string")
            value = data.decode("utf-8")
        elif typ in _NUMPY:
            width = 8 if typ == "double" else 4
            if kind == "L":
                if len(data) % width:
                    raise WireError(f"{message}.{name}: packed length not a multiple of {width}")
                value = np.frombuffer(data, dtype=_NUMPY[typ])
            elif kind == ("8" if width == 8 else "4"):
                value = np.frombuffer(data, dtype=_NUMPY[typ])
            else:
                raise WireError(f"{message}.{name}: wrong wire type")
            if not repeated:
                if value.size == 0:  # a packed scalar field with no value
                    raise WireError(f"{message}.{name}: empty value")
                value = value[0].item()
        elif typ == "bool":
            if kind == "L":
                value = np.frombuffer(data, dtype=np.uint8).astype(bool)
            elif kind == "v":
                value = np.array([bool(data)]) if repeated else bool(data)
            else:
                raise WireError(f"{message}.{name}: wrong wire type")
        else:  # uint32 / uint64
            if kind != "v":
                raise WireError(f"{message}.{name}: expected a varint")
            value = data
        if repeated:
            parts.setdefault(name, []).append(value)
        else:
            out[name] = value
    for name, _number, typ, repeated in _SPECS[message]:
        if repeated:
            chunks = parts.get(name, [])
            if typ.startswith("message:"):
                out[name] = chunks
            elif not chunks:
                dtype = bool if typ == "bool" else _NUMPY[typ]
                out[name] = np.zeros(0, dtype=dtype)
            elif len(chunks) == 1:
                out[name] = chunks[0]
            else:
                out[name] = np.concatenate(chunks)
        elif name not in out:
            out[name] = "" if typ == "string" else (False if typ == "bool" else 0)
    return out
