// A page's WebSocket (game.js: a live match, replay.js: a replay): the URL on the node that
// serves it, compact binary snapshots decoded and JSON text parsed, each message handed to
// the page's handler for its `type`, the server's `error`s kept for the tests, and a
// connection lost tried again with a growing wait, for up to 30 s (a restarting server
// resumes its matches within seconds: docs/operations.md).

import { CompactDecoder } from "./compact.js";

/** The first wait before a lost connection is tried again; each next wait doubles, up to
 * `RETRY_MAX_MS`, until `GIVE_UP_MS` have passed since the connection was lost. */
const RETRY_FIRST_MS = 250;
const RETRY_MAX_MS = 4000;
const GIVE_UP_MS = 30000;

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
    this.ws = null;
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
    const ws = new WebSocket(this.target());
    ws.binaryType = "arraybuffer";
    const decoder = new CompactDecoder();
    this.ws = ws;
    ws.onopen = () => {
      debug.connected = true;
      if (this.lostAt !== null) debug.reconnects = (debug.reconnects || 0) + 1;
      this.tries = 0;
      this.lostAt = null;
    };
    ws.onmessage = (m) => {
      const binary = typeof m.data !== "string";
      // What the page receives, for measurements of the bandwidth a client needs.
      debug.rxBytes = (debug.rxBytes || 0) + (binary ? m.data.byteLength : m.data.length);
      let msg;
      try { msg = binary ? decoder.decode(m.data) : JSON.parse(m.data); } catch (e) {
        debug.errors.push(String(e));
        return;
      }
      this.dispatch(msg);
    };
    ws.onclose = (e) => {
      debug.connected = false;
      if (this.page.lost(e)) return;
      const now = performance.now();
      if (this.lostAt === null) this.lostAt = now;
      if (now - this.lostAt < this.giveUpMs) {
        // 1012: the server is restarting and resumes the match, or the match moved to
        // another node (docs/api.md).
        status(e.code === 1012 ? "server restarting — reconnecting…" : "connection lost — reconnecting…");
        const wait = Math.min(RETRY_FIRST_MS * 2 ** this.tries++, RETRY_MAX_MS);
        setTimeout(() => { if (this.ws === ws) this.connect(); }, wait);
      } else {
        status("connection lost");
      }
    };
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
    return Boolean(this.ws) && this.ws.readyState === WebSocket.OPEN;
  }

  send(obj) {
    if (this.open) this.ws.send(JSON.stringify(obj));
  }

  /** Closes the socket the page is done with: no handler hears from it again. */
  close(code, reason) {
    const ws = this.ws;
    this.ws = null;
    if (!ws) return;
    ws.onmessage = null;
    ws.onclose = null;
    debug.connected = false;
    ws.close(code, reason);
  }
}
