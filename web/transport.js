// The two carriers under the page's socket (socket.js): a WebSocket, or a WebTransport
// session (docs/api.md, "WebTransport"), both opened with the same handlers and sending the
// same messages. Over WebTransport snapshots come as datagrams (a lost one costs that
// snapshot only), everything else in frames on the server's stream; inputs go as datagrams
// that repeat the last few, the rest in frames on the page's own stream, and the page says
// in a datagram which snapshots it holds (the server's deltas are against those).

/** How long a WebTransport session may take to open before the page takes the WebSocket
 * (UDP blocked drops the handshake silently: it would never fail by itself). */
export const WEBTRANSPORT_WAIT_MS = 1000;
/** The inputs each input datagram carries: the newest and the ones before it. */
const INPUTS_PER_DATAGRAM = 3;
const TEXT = 0;
/** A datagram's kind: which snapshots the page holds (`u32 newest | u32 bits`). */
const ACK = 2;
const utf8 = new TextDecoder();
const encode = (s) => new TextEncoder().encode(s);
/** The counters the tests read (`window.__lasertag`). */
const debug = (window.__lasertag = window.__lasertag || {});

/** A close the page sends on a carrier: counted, so tests can see there is one a session. */
function counted(kind) {
  debug.closesSent = (debug.closesSent || 0) + 1;
  debug.lastClose = kind;
}

/** What the node at `http` (its origin) offers besides the WebSocket: `GET /api/transport`'s
 * `webtransport` (its URL and the certificate hashes to pin), or null when it offers none. */
export async function transportOffer(http) {
  debug.transportFetches = (debug.transportFetches || 0) + 1;
  const info = await (await fetch(`${http}/api/transport`)).json();
  return (info && info.webtransport) || null;
}

/** The origin of the node a WebSocket URL names, over HTTP(S). */
export function httpOrigin(wsUrl) {
  const target = new URL(wsUrl);
  return `${target.protocol === "wss:" ? "https" : "http"}://${target.host}`;
}

/** Which carrier the page asks for: `localStorage["lasertag.transport"]` forces
 * `websocket` or `webtransport`; otherwise WebTransport where the browser has it. */
export function wantedTransport() {
  const forced = localStorage.getItem("lasertag.transport");
  if (forced === "websocket" || forced === "webtransport") return forced;
  return typeof WebTransport === "function" && window.isSecureContext ? "webtransport" : "websocket";
}

/** A WebSocket as a carrier: `on.open()`, `on.message(string | ArrayBuffer)`,
 * `on.close({code, reason})`. */
export function webSocketCarrier(url, on) {
  const ws = new WebSocket(url);
  ws.binaryType = "arraybuffer";
  ws.onopen = () => on.open();
  ws.onmessage = (m) => on.message(m.data);
  ws.onclose = (e) => on.close({ code: e.code, reason: e.reason });
  return {
    kind: "websocket",
    get open() { return ws.readyState === WebSocket.OPEN; },
    send(obj) { ws.send(JSON.stringify(obj)); },
    close(code, reason) {
      ws.onmessage = null;
      ws.onclose = null;
      // One close a session: none once the server's (the browser answered it) or ours is out.
      if (ws.readyState === WebSocket.CLOSING || ws.readyState === WebSocket.CLOSED) return;
      counted("websocket");
      ws.close(code, reason);
    },
  };
}

/** The bytes of a hex string. */
function hexBytes(hex) {
  const out = new Uint8Array(hex.length / 2);
  for (let i = 0; i < out.length; i++) out[i] = parseInt(hex.slice(2 * i, 2 * i + 2), 16);
  return out;
}

/** A WebTransport session to the socket a WebSocket URL names (`ws://host/ws/...?...`), on
 * the node at that host, with what that node offers (`transportOffer`, read by the caller
 * once for its session's node): resolves to a carrier once open, rejects when the server
 * offers none, the browser cannot, or it does not open within `WEBTRANSPORT_WAIT_MS`. */
export async function webTransportCarrier(wsUrl, on, at) {
  const target = new URL(wsUrl);
  if (!at) throw new Error("the server offers no WebTransport");
  const hashes = at.certificate_hashes.map((h) => ({ algorithm: h.algorithm, value: hexBytes(h.value) }));
  const wt = new WebTransport(`${at.url}${target.pathname}${target.search}`,
    hashes.length ? { serverCertificateHashes: hashes } : {});
  let timer;
  const late = new Promise((_, reject) => {
    timer = setTimeout(() => reject(new Error("WebTransport did not open in time")), WEBTRANSPORT_WAIT_MS);
  });
  try {
    await Promise.race([wt.ready, late]);
  } catch (e) {
    wt.close();
    throw e;
  } finally {
    clearTimeout(timer);
  }
  let closed = false;
  // Whether the page's close went out (the session's one).
  let sent = false;
  const end = () => {
    if (sent) return;
    sent = true;
    counted("webtransport");
    wt.close();
  };
  const finish = (how) => {
    if (closed) return;
    closed = true;
    on.close(how);
  };
  const out = await wt.createUnidirectionalStream();
  const writer = out.getWriter();
  const datagrams = wt.datagrams.writable.getWriter();
  const inputs = [];
  on.open();
  // The server's frames: [kind][length, u32 LE][payload]; its last says how it ends.
  (async () => {
    const streams = wt.incomingUnidirectionalStreams.getReader();
    const { value: stream } = await streams.read();
    if (!stream) return;
    const reader = stream.getReader();
    let buf = new Uint8Array(0);
    for (;;) {
      const { value, done } = await reader.read();
      if (done) break;
      const joined = new Uint8Array(buf.length + value.length);
      joined.set(buf);
      joined.set(value, buf.length);
      buf = joined;
      while (buf.length >= 5) {
        const len = new DataView(buf.buffer, buf.byteOffset + 1, 4).getUint32(0, true);
        if (buf.length < 5 + len) break;
        const payload = buf.slice(5, 5 + len);
        const kind = buf[0];
        buf = buf.slice(5 + len);
        if (kind === TEXT) {
          const text = utf8.decode(payload);
          const c = text.includes('"close"') ? JSON.parse(text) : null;
          if (c && c.type === "close") {
            finish({ code: c.code, reason: c.reason });
            end();
            return;
          }
          on.message(text);
        } else {
          on.message(payload.buffer);
        }
      }
    }
  })().catch(() => {});
  // Snapshots: [kind][message] a datagram.
  (async () => {
    const reader = wt.datagrams.readable.getReader();
    for (;;) {
      const { value, done } = await reader.read();
      if (done) break;
      const payload = value.subarray(1);
      on.message(value[0] === TEXT ? utf8.decode(payload) : payload.slice().buffer);
    }
  })().catch(() => {});
  wt.closed.then(
    (c) => finish({ code: (c && c.closeCode) || 1000, reason: (c && c.reason) || "" }),
    () => finish({ code: 1006, reason: "connection lost" }),
  );
  const frame = (text) => {
    const payload = encode(text);
    const f = new Uint8Array(5 + payload.length);
    f[0] = TEXT;
    new DataView(f.buffer).setUint32(1, payload.length, true);
    f.set(payload, 5);
    return writer.write(f);
  };
  return {
    kind: "webtransport",
    get open() { return !closed; },
    send(obj) {
      if (closed) return;
      if (obj.type === "input" && obj.seq !== undefined) {
        inputs.push(obj);
        if (inputs.length > INPUTS_PER_DATAGRAM) inputs.shift();
        const d = encode(JSON.stringify(inputs));
        const bytes = new Uint8Array(d.length + 1);
        bytes[0] = TEXT;
        bytes.set(d, 1);
        datagrams.write(bytes).catch(() => {});
      } else {
        frame(JSON.stringify(obj)).catch(() => {});
      }
    },
    /** Says which snapshots the page holds (`CompactDecoder.acks()`): a datagram. */
    ack(acks) {
      if (closed || !acks) return;
      const d = new Uint8Array(9);
      d[0] = ACK;
      const v = new DataView(d.buffer);
      v.setUint32(1, acks.newest, true);
      v.setUint32(5, acks.bits, true);
      datagrams.write(d).catch(() => {});
    },
    close() {
      closed = true;
      end();
    },
  };
}
