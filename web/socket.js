// A page's socket (game.js: a live match, replay.js: a replay), over WebTransport where it
// opens within a second and else a WebSocket (transport.js): the URL on the node that
// serves it, compact binary snapshots decoded and JSON text parsed, each message handed to
// the page's handler for its `type`, the server's `error`s kept for the tests, and a
// connection lost tried again with a growing wait, for up to 30 s (a restarting server
// resumes its matches within seconds: docs/operations.md).

import { CompactDecoder } from "./compact.js";
import {
  httpOrigin, transportOffer, wantedTransport, webSocketCarrier, webTransportCarrier,
} from "./transport.js";

/** The first wait before a lost connection is tried again; each next wait doubles, up to
 * `RETRY_MAX_MS`, until `GIVE_UP_MS` have passed since the connection was lost. */
const RETRY_FIRST_MS = 250;
const RETRY_MAX_MS = 4000;
const GIVE_UP_MS = 30000;
/** Over WebTransport the page says which snapshots it holds every this many it takes. */
const ACK_EVERY = 8;

/** The page's status line. */
const status = (text) => { document.getElementById("hud-status").textContent = text; };

/** The WebSocket URL of `path` on the node at `base` (its URL in a fleet listing), or on the
 * page's own server when `base` is empty. Browsers follow no redirect when opening a socket,
 * so the page goes to the match's node itself. */
export function socketUrl(base, path) {
  const at = base ? new URL(base) : location;
  return `${at.protocol === "https:" ? "wss" : "ws"}://${at.host}${path}`;
}

/** The counters the tests read (`window.__lasertag`, as the pages have it). */
const debug = (window.__lasertag = window.__lasertag || {});

export class PageSocket {
  /** The socket of `page`: `url()` is where to connect, asked on every try; `types` names
   * the page's method for each message type it reads (the others are dropped, an `error`
   * kept for the tests); `page.lost(e)` hears of a close the page did not ask for, and is
   * true when the page has dealt with it; otherwise the socket is tried again with a
   * growing wait, for `giveUpMs` at the most. */
  constructor(page, { url, types, giveUpMs = GIVE_UP_MS }) {
    Object.assign(this, { page, url, types, giveUpMs });
    this.tries = 0;
    this.lostAt = null;
    this.carrier = null;
    this.attempt = null;
    this.taken = 0;
    // What the node connected to offers (`GET /api/transport`): read once for the socket's
    // node, again only after a connection to it was lost (a restarted server has a new
    // certificate) or when the socket follows its match to another node.
    this.offer = null;
  }

  /** The WebTransport offer of the node at `origin`, read once (see `offer`). */
  offerOf(origin) {
    if (!this.offer || this.offer.origin !== origin) {
      const read = transportOffer(origin);
      this.offer = { origin, read };
      // A read that failed keeps nothing: the next try asks again.
      read.catch(() => { if (this.offer && this.offer.read === read) this.offer = null; });
    }
    return this.offer.read;
  }

  /** Where to connect now: `url()`, on the node the match moved to when it did. */
  target() {
    const url = new URL(this.url());
    if (!this.movedTo) return url.href;
    const to = new URL(this.movedTo);
    return `${to.protocol === "https:" ? "wss" : "ws"}://${to.host}${url.pathname}${url.search}`;
  }

  /** The match goes on on another node (`moved`, docs/api.md): its URL, or else the node
   * that `GET /api/matches/{id}` ends up at (a fleet redirects to the host). */
  async moved(msg) {
    debug.moved = (debug.moved || 0) + 1;
    if (msg.url) { this.movedTo = msg.url; return; }
    try {
      const path = new URL(this.target()).pathname.replace(/^\/ws\//, "/api/");
      const r = await fetch(path);
      if (r.ok) this.movedTo = new URL(r.url).origin;
    } catch { /* the next try asks again */ }
  }

  connect() {
    this.closed = false;
    const url = this.target();
    const decoder = new CompactDecoder();
    const token = {};
    this.attempt = token;
    const on = {
      open: () => {
        if (this.attempt !== token) return;
        debug.connected = true;
        if (this.lostAt !== null) debug.reconnects = (debug.reconnects || 0) + 1;
        this.tries = 0;
        this.lostAt = null;
      },
      message: (data) => {
        if (this.attempt !== token) return;
        const binary = typeof data !== "string";
        // What the page receives, for measurements of the bandwidth a client needs.
        debug.rxBytes = (debug.rxBytes || 0) + (binary ? data.byteLength : data.length);
        if (binary && new Uint8Array(data, 0, 1)[0] === 2) debug.deltas = (debug.deltas || 0) + 1;
        let msg;
        try { msg = binary ? decoder.decode(data) : JSON.parse(data); } catch (e) {
          debug.errors.push(String(e));
          return;
        }
        // Over a carrier that may lose snapshots, the server's deltas are against those the
        // page says it holds: every eighth snapshot. Each acknowledgement costs the server a
        // datagram to read and, on many round trips, a QUIC acknowledgement packet of its own
        // to send; a baseline some ticks older costs a delta a few bytes (docs/network.md).
        if (binary && this.carrier && this.carrier.ack && ++this.taken % ACK_EVERY === 0) {
          this.carrier.ack(decoder.acks());
        }
        this.dispatch(msg);
      },
      close: (e) => {
        if (this.attempt !== token) return;
        this.attempt = null;
        this.carrier = null;
        this.lost(e);
      },
    };
    const viaWebSocket = () => {
      this.carrier = webSocketCarrier(url, on);
      debug.transport = "websocket";
    };
    this.carrier = null;
    if (wantedTransport() !== "webtransport") return viaWebSocket();
    // WebTransport first; the WebSocket when it does not open within a second.
    const asked = performance.now();
    const stale = () => this.attempt !== token;
    this.offerOf(httpOrigin(url))
      .then((at) => (stale() ? Promise.reject(new Error("superseded")) : webTransportCarrier(url, on, at)))
      .then((carrier) => {
        if (stale()) return carrier.close();
        this.carrier = carrier;
        debug.transport = "webtransport";
      }, (e) => {
        if (stale()) return;
        debug.transportError = String(e);
        debug.fallbackMs = performance.now() - asked;
        viaWebSocket();
      });
  }

  /** The carrier closed without the page asking: tried again with a growing wait, unless
   * the page has dealt with it. */
  lost(e) {
    debug.connected = false;
    this.offer = null;
    if (this.page.lost(e)) return;
    const now = performance.now();
    if (this.lostAt === null) this.lostAt = now;
    if (now - this.lostAt < this.giveUpMs) {
      // 1012: the server is restarting and resumes the match, or the match moved to
      // another node (docs/api.md).
      status(e.code === 1012 ? "server restarting — reconnecting…" : "connection lost — reconnecting…");
      const wait = Math.min(RETRY_FIRST_MS * 2 ** this.tries++, RETRY_MAX_MS);
      setTimeout(() => { if (this.attempt === null && !this.closed) this.connect(); }, wait);
    } else {
      status("connection lost");
    }
  }

  dispatch(msg) {
    if (msg.type === "moved") return this.moved(msg);
    const method = this.types[msg.type];
    if (method) return this.page[method](msg);
    if (msg.type === "error") {
      debug.errors.push(msg.error);
      console.warn("server:", msg.error);
    }
  }

  /** Whether a message sent now goes out. */
  get open() {
    return Boolean(this.carrier) && this.carrier.open;
  }

  /** The carrier in use: `webtransport` or `websocket` (null while connecting). */
  get transport() {
    return this.carrier ? this.carrier.kind : null;
  }

  send(obj) {
    if (this.open) this.carrier.send(obj);
  }

  /** Closes the socket the page is done with: no handler hears from it again. */
  close(code, reason) {
    const carrier = this.carrier;
    this.closed = true;
    this.attempt = null;
    this.carrier = null;
    debug.connected = false;
    if (carrier) carrier.close(code, reason);
  }
}
