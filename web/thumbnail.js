// The lobby's live thumbnail: the showcase moving, as any spectator sees it (as late as the
// server shows a match people play), drawn small in the lobby so a visitor sees the game
// before choosing a door. One spectator socket while the lobby is shown and the tab visible;
// what it shows also writes the teaser beside it, so the words match the picture.

import { CompactDecoder } from "./compact.js";
import { segments } from "./geometry.js";
import { draw, fit } from "./render.js";
import { socketUrl } from "./socket.js";

/** The counters the tests read (`window.__lasertag`, as the pages have it). */
const debug = (window.__lasertag = window.__lasertag || {});

/** The wait before a lost thumbnail's socket is opened again. */
const RETRY_MS = 3000;

export class Thumbnail {
  /** Draws on `canvas`; `onView({ map, robots, alive, opponents, delayS })` hears what the
   * picture shows, once a second at most. */
  constructor(canvas, onView) {
    this.canvas = canvas;
    this.ctx = canvas.getContext("2d");
    this.onView = onView;
    this.id = null;
    this.ws = null;
    this.toldAt = 0;
    this.onVisibility = () => {
      if (document.hidden) this.disconnect();
      else if (this.id) this.connect();
    };
    document.addEventListener("visibilitychange", this.onVisibility);
    debug.thumbnail = { id: null, snapshots: 0 };
  }

  /** Shows match `id` on the node at `base` ("" for this server); the same match again
   * keeps its socket. */
  show(id, base) {
    if (id === this.id) return;
    this.disconnect();
    this.id = id;
    this.base = base;
    this.map = null;
    debug.thumbnail = { id, snapshots: 0 };
    if (!document.hidden) this.connect();
  }

  connect() {
    if (this.ws) return;
    const ws = new WebSocket(socketUrl(this.base, `/ws/matches/${encodeURIComponent(this.id)}?format=compact`));
    ws.binaryType = "arraybuffer";
    const decoder = new CompactDecoder();
    this.ws = ws;
    ws.onmessage = (m) => {
      let msg;
      try {
        msg = typeof m.data === "string" ? JSON.parse(m.data) : decoder.decode(m.data);
      } catch {
        return;
      }
      if (msg.type === "welcome") this.welcome(ws, msg);
      else if (msg.type === "snapshot" && this.map) this.snapshot(msg);
    };
    ws.onclose = () => {
      if (this.ws !== ws) return;
      this.ws = null;
      setTimeout(() => { if (this.id && !this.ws && !document.hidden) this.connect(); }, RETRY_MS);
    };
  }

  welcome(ws, w) {
    this.map = w.map;
    this.segs = segments(w.map);
    this.delayS = w.spectator_delay_s || 0;
    // A thumbnail has no room for the belief's clouds: they are the arena page's.
    if (w.belief) ws.send(JSON.stringify({ type: "belief", on: false }));
  }

  snapshot(s) {
    const v = fit(this.canvas, this.map, { hud: false });
    draw(this.ctx, v, {
      map: this.map, segs: this.segs, you: null, robots: s.robots, opponents: s.opponents,
      visible: null, belief: null, beams: [], now: performance.now(),
    });
    debug.thumbnail.snapshots++;
    debug.thumbnail.tick = s.tick;
    const now = performance.now();
    if (now - this.toldAt < 1000) return;
    this.toldAt = now;
    const alive = s.opponents.filter((o) => !o.tagged).length;
    const view = {
      map: this.map.name, robots: s.robots.length, alive, opponents: s.score.opponents,
      delayS: this.delayS,
    };
    debug.thumbnail.view = view;
    this.onView(view);
  }

  disconnect() {
    const ws = this.ws;
    this.ws = null;
    if (ws) {
      ws.onclose = null;
      ws.onmessage = null;
      ws.close(1000, "lobby left");
    }
  }

  /** Leaves the match: the socket closes and stays closed until `show` is called again. */
  stop() {
    this.disconnect();
    this.id = null;
  }
}
