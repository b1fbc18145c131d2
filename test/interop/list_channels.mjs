// List the channels of an MCAP file and count the messages of each, with @mcap/core.
// Usage: node list_channels.mjs FILE.mcap  ->  JSON {"topic": {"schema": ..., "count": n}}
import { open } from 'node:fs/promises';
import { McapStreamReader } from '@mcap/core';

const handle = await open(process.argv[2], 'r');
const bytes = await handle.readFile();
await handle.close();
const reader = new McapStreamReader({ validateCrcs: true });
reader.append(bytes);
const schemas = new Map();
const channels = new Map();
const out = {};
for (let record; (record = reader.nextRecord()) !== undefined;) {
  if (record.type === 'Schema') {
    schemas.set(record.id, record.name);
  } else if (record.type === 'Channel') {
    channels.set(record.id, record.topic);
    out[record.topic] ??= { schema: schemas.get(record.schemaId), encoding: record.messageEncoding, count: 0 };
  } else if (record.type === 'Message') {
    out[channels.get(record.channelId)].count += 1;
  }
}
if (!reader.done()) {
  throw new Error('truncated MCAP file');
}
console.log(JSON.stringify(out));
