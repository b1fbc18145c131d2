// Watch a Foxglove WebSocket server with the protocol's published client, @foxglove/ws-protocol.
// Usage: node foxglove_client.mjs URL TOPIC[,TOPIC...] [ORIGIN]
// Offers only the subprotocol that client library names (foxglove.websocket.v1), subscribes
// to the topics once advertised and prints one JSON line per event:
//   {"event": "open", "protocol": ...}, {"event": "advertise", "channels": [...]},
//   {"event": "message", "topic", "encoding", "logTime" (ns, a string), "data" (decoded)},
//   {"event": "error", "message"}, {"event": "close", "code"}.
// Runs until the server closes the connection or stdin ends.
import wsProtocol from '@foxglove/ws-protocol';  // a CommonJS module: no named exports
import WebSocket from 'ws';

const { FoxgloveClient } = wsProtocol;

const [url, topicList, origin] = process.argv.slice(2);
const wanted = new Set(topicList.split(','));
const print = (line) => process.stdout.write(JSON.stringify(line) + '\n');
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL],
  origin ? { origin } : {});
ws.on('open', () => print({ event: 'open', protocol: ws.protocol }));
ws.on('unexpected-response', (_request, response) => {
  print({ event: 'error', message: `HTTP ${response.statusCode}` });
  process.exit(1);
});
const client = new FoxgloveClient({ ws });
const subscriptions = new Map();
const decoder = new TextDecoder();

client.on('advertise', (channels) => {
  print({
    event: 'advertise',
    channels: channels.map((c) => ({ topic: c.topic, encoding: c.encoding, schemaName: c.schemaName })),
  });
  for (const channel of channels) {
    if (wanted.has(channel.topic)) {
      subscriptions.set(client.subscribe(channel.id), channel);
    }
  }
});
client.on('message', ({ subscriptionId, timestamp, data }) => {
  const channel = subscriptions.get(subscriptionId);
  if (channel === undefined) {
    return;
  }
  if (channel.encoding !== 'json') {
    print({ event: 'message', topic: channel.topic, encoding: channel.encoding, logTime: timestamp.toString() });
    return;
  }
  print({
    event: 'message', topic: channel.topic, encoding: channel.encoding,
    logTime: timestamp.toString(), data: JSON.parse(decoder.decode(data)),
  });
});
client.on('error', (error) => print({ event: 'error', message: String(error?.message ?? error) }));
client.on('close', (event) => {
  print({ event: 'close', code: event.code });
  process.exit(0);
});
process.stdin.on('end', () => client.close());
process.stdin.resume();
