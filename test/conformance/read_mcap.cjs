// Read MCAP files as Foxglove does and print, as JSON, what was decoded.
//
// usage: node read_mcap.cjs NODE_MODULES_DIR FILE...
//
// Every file is opened with @mcap/core's indexed reader (summary, chunk and metadata indexes,
// zstd chunks through @foxglove/wasm-zstd); every schema is parsed with @foxglove/rosmsg in
// ROS 2 mode and every message decoded with @foxglove/rosmsg2-serialization, as Foxglove's
// ros2msg channels are. A schema that does not parse, or a message that does not decode, is an
// error for that topic; the script never stops at the first one.
"use strict";

const fs = require("node:fs/promises");
const path = require("node:path");
const { createRequire } = require("node:module");

const load = createRequire(path.join(path.resolve(process.argv[2]), "package.json"));
const { McapIndexedReader } = load("@mcap/core");
const { parse } = load("@foxglove/rosmsg");
const { MessageReader } = load("@foxglove/rosmsg2-serialization");
const zstd = load("@foxglove/wasm-zstd");

function fileReadable(handle, size) {
  return {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      await handle.read(buffer, 0, Number(length), Number(offset));
      return buffer;
    },
  };
}

// Figures that show the values were decoded, not only the bytes walked through.
function tally(topic, message) {
  if (Array.isArray(message.skeletons)) {
    topic.items += message.skeletons.length;
    topic.joints += message.skeletons.reduce((n, s) => n + s.markers.length, 0);
  } else if (Array.isArray(message.markers)) {
    topic.items += message.markers.length;
    topic.joints += message.markers.reduce((n, m) => n + m.points.length, 0);
  } else if (Array.isArray(message.transforms)) {
    topic.items += message.transforms.length;
  } else if (typeof message.data === "string") {
    topic.items += message.data.length > 0 ? 1 : 0;
  }
}

async function readFile(file) {
  const stat = await fs.stat(file);
  const handle = await fs.open(file, "r");
  try {
    const reader = await McapIndexedReader.Initialize({
      readable: fileReadable(handle, stat.size),
      decompressHandlers: { zstd: (data, size) => zstd.decompress(data, Number(size)) },
    });
    const readers = new Map();
    const topics = {};
    for (const [id, channel] of reader.channelsById) {
      const schema = reader.schemasById.get(channel.schemaId);
      const topic = (topics[channel.topic] = {
        schema: schema.name,
        encoding: `${channel.messageEncoding}/${schema.encoding}`,
        channel_metadata: Object.fromEntries(channel.metadata),
        messages: 0,
        decoded: 0,
        trailing: 0,
        items: 0,
        joints: 0,
        errors: [],
        first_log_time: null,
        last_log_time: null,
      });
      try {
        const text = new TextDecoder().decode(schema.data);
        readers.set(id, new MessageReader(parse(text, { ros2: true })));
      } catch (error) {
        topic.errors.push(`schema: ${error.message}`);
      }
    }
    for await (const message of reader.readMessages()) {
      const topic = topics[reader.channelsById.get(message.channelId).topic];
      const time = message.logTime.toString();
      topic.messages += 1;
      topic.first_log_time ??= time;
      topic.last_log_time = time;
      const decoder = readers.get(message.channelId);
      if (decoder === undefined) continue;
      try {
        tally(topic, decoder.readMessage(message.data));
        topic.decoded += 1;
        if (decoder.lastReadHadTrailingBytes()) topic.trailing += 1;
      } catch (error) {
        if (topic.errors.length < 5) topic.errors.push(`message: ${error.message}`);
      }
    }
    const metadata = [];
    for await (const record of reader.readMetadata()) {
      metadata.push({ name: record.name, keys: [...record.metadata.keys()].sort() });
    }
    const statistics = reader.statistics;
    return {
      profile: reader.header.profile,
      message_start_time: statistics?.messageStartTime.toString() ?? null,
      message_end_time: statistics?.messageEndTime.toString() ?? null,
      metadata,
      topics,
    };
  } finally {
    await handle.close();
  }
}

async function main() {
  await zstd.isLoaded;
  const out = {};
  for (const file of process.argv.slice(3)) {
    try {
      out[file] = await readFile(file);
    } catch (error) {
      out[file] = { error: error.message };
    }
  }
  process.stdout.write(JSON.stringify(out));
}

main().catch((error) => {
  process.stderr.write(`${error.stack}\n`);
  process.exit(1);
});
