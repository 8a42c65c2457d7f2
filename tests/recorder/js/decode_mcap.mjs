// Decode every message of an ISAAC MCAP log with Foxglove's TypeScript stack (@mcap/core's
// indexed reader, protobufjs built from the FileDescriptorSet stored as each channel's schema)
// and print, as JSON, the message count per topic and every float of the first and last
// /bodies message, for tests/recorder/test_recorder_foxglove_ts.py to compare bit for bit.
import { McapIndexedReader } from "@mcap/core";
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
const reader = await McapIndexedReader.Initialize({ readable });
const types = new Map();
for (const [id, schema] of reader.schemasById) {
  const root = protobuf.Root.fromDescriptor(descriptor.FileDescriptorSet.decode(schema.data));
  types.set(id, root.lookupType(schema.name));
}
const counts = {};
const bodies = [];
for await (const msg of reader.readMessages()) {
  const channel = reader.channelsById.get(msg.channelId);
  const type = types.get(channel.schemaId);
  const decoded = type.toObject(type.decode(msg.data), { longs: String, defaults: true });
  counts[channel.topic] = (counts[channel.topic] ?? 0) + 1;
  if (channel.topic === "/bodies") bodies.push(decoded);
}
const pick = (m) => ({ step: Number(m.step), position: m.position, velocity: m.velocity,
                      angle: m.angle,
                      angularVelocity: m.angularVelocity ?? m.angular_velocity });
// numbers are written by JSON.stringify as the shortest round-trip decimal, as Python's repr
console.log(JSON.stringify({ counts, first: pick(bodies[0]), last: pick(bodies.at(-1)) }));
await fh.close();
