// A client of Foxglove's WebSocket protocol (subprotocol foxglove.sdk.v1, which tlt-live-bridge
// serves): it learns the server's channels from its "advertise" messages, subscribes to the topics
// it is asked for as soon as they are offered, and hands each message's payload to the topic's
// handler, decoded from CDR with the channel's ros2msg schema. A latched topic (sent once, kept for
// late subscribers: the robot description, /tf_static, the markers) that has sent nothing a few
// seconds after the subscription is asked for again: the bridge then makes a fresh ROS
// subscription, with the QoS its publishers offer by then, which gets the kept message.

import { cdrDecoder } from "./ros2msg_cdr.js";

const SUBPROTOCOL = "foxglove.sdk.v1";
const MESSAGE_DATA = 0x01; // the server's binary opcode of a subscribed message
const LATCHED_RETRY_MS = 5000;

export class FoxgloveClient {
  // url: ws://host:port; handlers: topic -> function(message, logTimeNs); latched: the topics
  // asked for again while silent, every retryMs; onStatus(text, connected).
  constructor(url, handlers, latched, onStatus, retryMs = LATCHED_RETRY_MS) {
    this.url = url;
    this.retryMs = retryMs;
    this.handlers = handlers;
    this.latched = new Set(latched);
    this.resubscribed = 0;
    this.onStatus = onStatus;
    this.subscriptions = new Map(); // subscription id -> {topic, decode}
    this.subscribedChannels = new Set();
    this.nextId = 1;
    this.received = {}; // topic -> messages received (0: subscribed, none yet)
    this.errors = [];
    this.connect();
  }

  connect() {
    this.onStatus(`connecting to ${this.url}`, false);
    const ws = new WebSocket(this.url, [SUBPROTOCOL]);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => this.onStatus(`connected to ${this.url}`, true);
    ws.onmessage = (event) => (typeof event.data === "string" ? this.onJson(JSON.parse(event.data)) : this.onBinary(event.data));
    ws.onclose = () => {
      this.subscriptions.clear();
      this.subscribedChannels.clear();
      this.onStatus(`no bridge at ${this.url}: retrying`, false);
      setTimeout(() => this.connect(), 2000);
    };
    this.ws = ws;
  }

  onJson(msg) {
    if (msg.op !== "advertise") return;
    const wanted = [];
    for (const channel of msg.channels) {
      if (!(channel.topic in this.handlers) || this.subscribedChannels.has(channel.id)) continue;
      if (channel.encoding !== "cdr" || channel.schemaEncoding !== "ros2msg") {
        this.errors.push(`${channel.topic}: ${channel.encoding}/${channel.schemaEncoding} is not cdr/ros2msg`);
        continue;
      }
      const id = this.nextId++;
      this.subscriptions.set(id, { topic: channel.topic, decode: cdrDecoder(channel.schemaName, channel.schema) });
      this.subscribedChannels.add(channel.id);
      this.received[channel.topic] = 0;
      wanted.push({ id, channelId: channel.id });
      if (this.latched.has(channel.topic)) this.retryWhileSilent(this.ws, id, channel.id);
    }
    if (wanted.length) this.ws.send(JSON.stringify({ op: "subscribe", subscriptions: wanted }));
  }

  retryWhileSilent(ws, id, channelId) {
    setTimeout(() => {
      const subscription = this.subscriptions.get(id);
      if (ws !== this.ws || ws.readyState !== WebSocket.OPEN || !subscription) return;
      if (this.received[subscription.topic] > 0) return;
      const again = this.nextId++;
      this.subscriptions.delete(id);
      this.subscriptions.set(again, subscription);
      this.resubscribed += 1;
      ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [id] }));
      ws.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: again, channelId }] }));
      this.retryWhileSilent(ws, again, channelId);
    }, this.retryMs);
  }

  onBinary(buffer) {
    const view = new DataView(buffer);
    if (view.getUint8(0) !== MESSAGE_DATA) return;
    const subscription = this.subscriptions.get(view.getUint32(1, true));
    if (!subscription) return;
    const logTime = view.getBigUint64(5, true);
    try {
      const message = subscription.decode(new Uint8Array(buffer, 13));
      this.received[subscription.topic] += 1;
      this.handlers[subscription.topic](message, logTime);
    } catch (err) {
      this.errors.push(`${subscription.topic}: ${err.message}`);
      console.error(subscription.topic, err);
    }
  }
}
