// Decode every message of an ISAAC MCAP log with Foxglove's TypeScript stack (@mcap/core's
// indexed reader, protobufjs built from the FileDescriptorSet stored as each channel's schema)
// and print, as JSON, the message count per topic, every float of the first and last /bodies
// message and every field of the last /contacts message holding contacts (per manifold and per
// point, format 2), for tests/recorder/test_recorder_foxglove_ts.py to compare bit for bit.
import { McapIndexedReader } from "@mcap/core";
import { loadDecompressHandlers } from "@mcap/support";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";
import { open } from "node:fs/promises";

const fh = await open(process.argv[2], "r");
const size = (await fh.stat()).size;
const readable = {
  size: async () => BigInt(size),
  read: async (offset, length) => {
    const buf = new Uint8Array(Number(length));
    await fh.read(buf, 0, Number(length), Number(offset));
    return buf;
  },
};
// lz4 and zstd chunks: the handlers Foxglove's own MCAP loading uses (@mcap/support, wasm)
const decompressHandlers = await loadDecompressHandlers();
const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
const types = new Map();
for (const [id, schema] of reader.schemasById) {
  const root = protobuf.Root.fromDescriptor(descriptor.FileDescriptorSet.decode(schema.data));
  types.set(id, root.lookupType(schema.name));
}
const counts = {};
const bodies = [];
let contacts = null;
let joints = null;
let world = null;
for await (const msg of reader.readMessages()) {
  const channel = reader.channelsById.get(msg.channelId);
  const type = types.get(channel.schemaId);
  const decoded = type.toObject(type.decode(msg.data), { longs: String, defaults: true });
  counts[channel.topic] = (counts[channel.topic] ?? 0) + 1;
  if (channel.topic === "/bodies") bodies.push(decoded);
  if (channel.topic === "/contacts" && decoded.a.length) contacts = decoded;
  if (channel.topic === "/joints") joints = decoded;
  if (channel.topic === "/world" && world === null) world = decoded;
}
const pick = (m) => ({ step: Number(m.step), position: m.position, velocity: m.velocity,
                      angle: m.angle,
                      angularVelocity: m.angularVelocity ?? m.angular_velocity });
// protobufjs names a field by its name or its JSON name, depending on how the root was built
const field = (m, snake) => m[snake] ?? m[snake.replace(/_(.)/g, (_, c) => c.toUpperCase())];
const CONTACT_FIELDS = ["substep", "a", "b", "feature", "points", "normal", "pair_depth",
                        "pushed", "push_a", "push_b", "point", "point_depth", "impulse", "tangent_impulse",
                        "restitution"];
const pickContacts = (m) => Object.fromEntries(
  [["step", Number(m.step)], ...CONTACT_FIELDS.map((f) => [f, field(m, f)])]);
const JOINTS_FIELDS = ["anchor_a", "anchor_b", "linear_impulse", "angular_impulse",
                       "motor_impulse", "limit_impulse", "error", "impulses"];
const pickJoints = (m) => Object.fromEntries(
  [["step", Number(m.step)], ...JOINTS_FIELDS.map((f) => [f, field(m, f)])]);
// the joint table (a scene with joints): infinite limits as strings (JSON has no infinity)
const JOINT_FIELDS = ["index", "name", "type", "a", "b", "local_a", "local_b", "axis",
                      "reference_angle", "length", "min_length", "max_length", "stiffness",
                      "damping_ratio", "lower", "upper", "motor_speed", "max_motor", "spring",
                      "motor", "collide_connected"];
const finite = (x) => (typeof x === "number" && !Number.isFinite(x) ? String(x) : x);
const pickJoint = (j) => Object.fromEntries(JOINT_FIELDS.map((f) => [f, finite(field(j, f))]));
// numbers are written by JSON.stringify as the shortest round-trip decimal, as Python's repr
console.log(JSON.stringify({ counts, first: pick(bodies[0]), last: pick(bodies.at(-1)),
                             contacts: contacts && pickContacts(contacts),
                             joints: joints && pickJoints(joints),
                             jointTable: world && (world.joints ?? []).map(pickJoint) }));
await fh.close();
