// One match in the browser: the WebSocket, smooth motion between snapshots, the keyboard,
// the HUD (score, timer, ping, tag feed) and the end screen.

import { segments, visibility, castRay, angleDiff } from "./geometry.js";
import { draw, fit, roleColor } from "./render.js";
import { Predictor } from "./predict.js";
import { CompactDecoder } from "./compact.js";
import { rules } from "./rules.js";

const $ = (id) => document.getElementById(id);
const TICK_MS = 50;
/** Other agents are drawn this much later than the snapshots' steady arrival, plus what the
 * measured jitter needs (most arrivals in time to interpolate), in milliseconds... */
const MARGIN_MS = 10;
/** ...between these bounds (ticks behind the newest snapshot's time). */
const MIN_DELAY_TICKS = 0.3;
const MAX_DELAY_TICKS = 4;
/** A snapshot that is late is bridged by extrapolating this many ticks at most, not frozen. */
const MAX_EXTRAPOLATE_TICKS = 2;
/** Arrivals kept to measure the jitter. */
const JITTER_WINDOW = 60;

/** What tests read: counts of what was drawn, the feed, the end. */
export const debug = (window.__lasertag = window.__lasertag || {});

/** The WebSocket URL of `path` on the node at `base` (its URL in a fleet listing), or on the
 * page's own server when `base` is empty. Browsers follow no redirect when opening a socket,
 * so the page goes to the match's node itself. */
export function socketUrl(base, path) {
  const at = base ? new URL(base) : location;
  return `${at.protocol === "https:" ? "wss" : "ws"}://${at.host}${path}`;
}

function fmtTime(s) {
  s = Math.max(0, Math.floor(s));
  return `${Math.floor(s / 60)}:${String(s % 60).padStart(2, "0")}`;
}

export class Game {
  constructor({ matchId, token, base = "", onLobby, onReplay, onStaleToken }) {
    this.matchId = matchId;
    this.token = token;
    // The node that hosts the match, in a fleet ("" for this page's own server).
    this.base = base;
    this.onLobby = onLobby;
    this.onReplay = onReplay;
    this.onStaleToken = onStaleToken;
    this.welcomed = false;
    this.canvas = $("arena");
    this.ctx = this.canvas.getContext("2d");
    this.snaps = [];
    this.offset = null;
    this.lateness = []; // recent arrivals' lateness (ms) against the steadiest one
    this.delayTicks = MAX_DELAY_TICKS / 2;
    this.beams = [];
    this.names = {};
    this.keys = new Set();
    this.beliefOn = !token;
    this.belief = null;
    // Numbered inputs, one per 50 ms tick (see predict.js).
    this.seq = 0;
    this.tickAt = null;
    this.tagLatch = false;
    this.predictor = null;
    this.renderTick = null;
    this.ended = null;
    this.closedByUs = false;
    this.retries = 0;
    Object.assign(debug, {
      page: "game", matchId, base, role: token ? "player" : "spectator", connected: false,
      snapshots: 0, lastTick: null, drawn: null, feed: [], ended: null, ping: null, you: null,
      belief: this.beliefOn, errors: [],
    });
    $("feed").replaceChildren();
    $("end").hidden = true;
    $("hud-status").textContent = "connecting…";
    this.onKey = (e) => this.key(e);
    window.addEventListener("keydown", this.onKey);
    window.addEventListener("keyup", this.onKey);
    this.onBlur = () => { this.keys.clear(); };
    window.addEventListener("blur", this.onBlur);
    $("end-lobby").onclick = () => this.onLobby();
    $("end-replay").onclick = () => this.onReplay(this);
    $("end-watch").hidden = true;
    this.connect();
    this.pingTimer = setInterval(() => this.send({ type: "ping", t: performance.now() }), 1000);
    this.inputTimer = setInterval(() => this.inputTicks(performance.now()), 10);
    const loop = (t) => { if (!this.stopped) { this.frame(t); requestAnimationFrame(loop); } };
    requestAnimationFrame(loop);
  }

  stop() {
    this.stopped = true;
    this.closedByUs = true;
    clearInterval(this.pingTimer);
    clearInterval(this.inputTimer);
    window.removeEventListener("keydown", this.onKey);
    window.removeEventListener("keyup", this.onKey);
    window.removeEventListener("blur", this.onBlur);
    if (this.ws) this.ws.close(1000, "left");
  }

  connect() {
    // Snapshots in the compact binary form (see compact.js); the rest stays JSON text.
    const q = `?format=compact${this.token ? `&token=${encodeURIComponent(this.token)}` : ""}`;
    const ws = new WebSocket(socketUrl(this.base, `/ws/matches/${encodeURIComponent(this.matchId)}${q}`));
    ws.binaryType = "arraybuffer";
    this.decoder = new CompactDecoder();
    this.ws = ws;
    ws.onopen = () => { debug.connected = true; this.retries = 0; };
    ws.onmessage = (m) => {
      const binary = typeof m.data !== "string";
      // What the page receives, for measurements of the bandwidth a client needs.
      debug.rxBytes = (debug.rxBytes || 0) + (binary ? m.data.byteLength : m.data.length);
      let msg;
      try { msg = binary ? this.decoder.decode(m.data) : JSON.parse(m.data); } catch (e) {
        debug.errors.push(String(e));
        return;
      }
      this.message(msg);
    };
    ws.onclose = (e) => {
      debug.connected = false;
      if (this.closedByUs || this.stopped) return;
      if (this.token && !this.welcomed && this.onStaleToken) {
        // Refused before the first message: the stored token's slot was freed. Join again.
        this.stop();
        this.onStaleToken();
        return;
      }
      if (e.code === 1008) {
        $("hud-status").textContent = `disconnected: ${e.reason}`;
        return;
      }
      if (this.ended && (e.code === 1000 || e.code === 1001)) {
        // The match ended and was removed, or the server shut down: the end screen stays.
        return;
      }
      // Players keep their opponent for a while: try to come back.
      if (this.retries++ < 20) {
        $("hud-status").textContent = "connection lost — reconnecting…";
        setTimeout(() => this.connect(), 1000);
      } else {
        $("hud-status").textContent = "connection lost";
      }
    };
  }

  send(obj) {
    if (this.ws && this.ws.readyState === WebSocket.OPEN) this.ws.send(JSON.stringify(obj));
  }

  message(msg) {
    switch (msg.type) {
      case "welcome": return this.welcome(msg);
      case "snapshot": return this.snapshot(msg);
      case "event": return this.event(msg);
      case "finished": return this.finished(msg);
      case "pong": {
        const rtt = performance.now() - msg.t;
        debug.ping = rtt;
        const jitter = debug.jitterMs || 0;
        // A hint a player can act on: what the round trip and the jitter will feel like.
        const quality = rtt < 120 && jitter < 40 ? "good" : rtt < 250 && jitter < 100 ? "fair" : "poor";
        $("hud-ping").textContent = `ping ${rtt.toFixed(0)} ms · jitter ${jitter.toFixed(0)} ms · ${quality}`;
        $("hud-ping").dataset.quality = quality;
        return;
      }
      case "error":
        debug.errors.push(msg.error);
        console.warn("server:", msg.error);
        return;
    }
  }

  welcome(w) {
    this.welcomed = true;
    this.map = w.map;
    this.segs = segments(w.map);
    this.you = w.you;
    this.role = w.role;
    this.tickHz = w.tick_hz;
    // A match people play is shown to spectators late (so that nobody can watch where the
    // robots are while playing them): say so, wherever the page shows everything.
    this.delay = w.spectator_delay_s > 0 ? `${Math.round(w.spectator_delay_s)} s behind` : "";
    debug.you = w.you;
    debug.role = w.role;
    debug.delay = w.spectator_delay_s;
    if (w.belief !== this.beliefOn) this.send({ type: "belief", on: this.beliefOn });
    // A (re)connection numbers its inputs from 1 again, and predicts only as a player.
    this.seq = 0;
    this.tickAt = null;
    // (`localStorage["lasertag.predict"] = "off"` turns prediction off, to measure what it buys.)
    const predict = w.role === "player" && w.kinematics && localStorage.getItem("lasertag.predict") !== "off";
    this.predictor = predict ? new Predictor(w.map, this.segs, w.kinematics) : null;
    const watching = this.delay ? `spectating, delayed ${this.delay}` : "spectating";
    $("hud-match").textContent = `${w.map.name} · ${w.role === "player" ? `playing ${w.you} (${w.name})` : watching}`;
    $("hud-status").textContent = "";
    $("controls").innerHTML = w.role === "player"
      ? "<kbd>W</kbd><kbd>A</kbd><kbd>S</kbd><kbd>D</kbd> / arrows move and turn · <kbd>Space</kbd> tag · <kbd>B</kbd> robots' belief"
      : `spectating${this.delay ? ` (delayed ${this.delay}: people are playing)` : ""}: true positions, scans, goals and belief · <kbd>B</kbd> belief on/off`;
  }

  snapshot(s) {
    const now = performance.now();
    const sample = now - s.tick * TICK_MS;
    if (this.snaps.length && s.tick < this.snaps[this.snaps.length - 1].tick) {
      // Time went back (a tagged player now watches as late as spectators): start over.
      this.snaps = [];
      this.offset = sample;
      this.lateness = [];
    }
    // The offset follows the earliest arrivals (least delayed), drifting up slowly.
    this.offset = this.offset === null ? sample : Math.min(this.offset + 0.5, sample);
    this.lateness.push(sample - this.offset);
    if (this.lateness.length > JITTER_WINDOW) this.lateness.shift();
    // Draw as late as 95% of arrivals need, so interpolation seldom runs out of snapshots.
    const sorted = [...this.lateness].sort((a, b) => a - b);
    const jitter = sorted[Math.floor(0.95 * (sorted.length - 1))];
    this.delayTicks = Math.max(MIN_DELAY_TICKS, Math.min(MAX_DELAY_TICKS, (jitter + MARGIN_MS) / TICK_MS));
    debug.jitterMs = jitter;
    debug.delayMs = this.delayTicks * TICK_MS;
    this.snaps.push(s);
    if (this.snaps.length > 12) this.snaps.shift();
    if (s.belief) this.belief = s.belief;
    if (this.predictor && s.view === "player" && s.ack !== undefined) {
      const me = s.opponents.find((o) => o.id === this.you);
      const others = [...s.robots, ...s.opponents].filter((a) => a !== me && !a.tagged).map((a) => [a.x, a.y]);
      if (me) this.predictor.reconcile(me, s.ack, others);
      debug.ack = s.ack;
      debug.corrections = this.predictor.corrections;
    } else if (s.view === "spectator") {
      this.predictor = null; // tagged: nothing of ours moves any more
    }
    for (const o of s.opponents) if (o.name) this.names[o.id] = o.name;
    debug.snapshots++;
    debug.lastTick = s.tick;
    debug.view = s.view;
    const sc = s.score;
    $("hud-score").textContent =
      `robots tagged ${sc.tags}/${sc.opponents} opponents · opponents tagged robots ${sc.robot_tags}×`;
    $("hud-timer").textContent = fmtTime(s.time_left_s);
    if (this.role === "player" && s.view === "spectator" && !this.ended) {
      $("hud-status").textContent = `you were tagged — spectating${this.delay ? `, delayed ${this.delay}` : ""}`;
    }
    this.legend();
  }

  who(id) {
    return this.names[id] ? `${this.names[id]}` : id;
  }

  event(e) {
    const latest = this.snaps[this.snaps.length - 1];
    let text = null;
    let cls = e.kind;
    switch (e.kind) {
      case "shot": this.beam(e, latest); break;
      case "tag": text = `${this.who(e.by)} tagged ${e.target === this.you ? "you" : this.who(e.target)}`; break;
      case "robot_tagged": text = `${e.by === this.you ? "you" : this.who(e.by)} tagged ${e.target} (frozen 10 s)`; break;
      case "role_split": text = `belief: role ${e.role} split from ${e.from}`; cls = "role"; break;
      case "role_merge": text = `belief: role ${e.from} merged into ${e.role} (${e.count})`; cls = "role"; break;
      case "player_joined": text = `${e.name} joined as ${e.opponent}`; this.names[e.opponent] = e.name; break;
      case "player_left": text = `${e.name} left`; break;
      case "finished":
        text = e.winner ? `match over: ${e.winner} win` : `match over: ${e.reason.replace("_", " ")}`;
        break;
    }
    if (!text) return;
    debug.feed.push({ kind: e.kind, text, seq: e.seq });
    const li = document.createElement("li");
    li.className = cls;
    li.textContent = text;
    const feed = $("feed");
    feed.prepend(li);
    while (feed.children.length > 8) feed.lastChild.remove();
  }

  beam(e, snap) {
    if (!snap) return;
    const all = [...snap.robots, ...snap.opponents];
    const from = all.find((a) => a.id === e.by);
    if (!from) return; // out of sight
    const to = e.hit && all.find((a) => a.id === e.hit);
    let x2, y2;
    if (to) { x2 = to.x; y2 = to.y; } else {
      const dx = Math.cos(from.theta), dy = Math.sin(from.theta);
      const reach = rules.tag.range;
      const r = this.segs ? castRay(this.segs, from.x, from.y, dx, dy, reach) : reach;
      x2 = from.x + dx * r; y2 = from.y + dy * r;
    }
    const color = e.by.startsWith("r") ? "#9fdcff" : "#ff6b8b";
    this.beams.push({ x1: from.x, y1: from.y, x2, y2, t0: performance.now(), color });
    if (this.beams.length > 20) this.beams.shift();
  }

  finished(f) {
    this.ended = f;
    debug.ended = f;
    const won = f.winner === "robots" ? "The robots win"
      : f.winner === "opponents" ? "The opponents win" : "Match over";
    const why = {
      all_tagged: `every opponent was tagged after ${fmtTime(f.time_s)}`,
      time_limit: `the opponents held out for ${fmtTime(f.time_s)}`,
      stopped: `the match was stopped at ${fmtTime(f.time_s)}`,
      server_shutdown: `the server shut down at ${fmtTime(f.time_s)}`,
      abandoned: `nobody was playing; the match was ended at ${fmtTime(f.time_s)}`,
      overloaded: `the server could not keep up with this match; it was ended at ${fmtTime(f.time_s)}`,
    }[f.reason] || `at ${fmtTime(f.time_s)}`;
    let you = "";
    if (this.role === "player" && f.winner) {
      you = f.winner === "opponents" ? " — you win!" : " — you lose.";
    }
    // The replay from this player's own view: how the robots found it (see replay.js).
    const watch = $("end-watch");
    watch.hidden = this.role !== "player" || !this.you;
    watch.onclick = () => (location.hash = `#/replay/${encodeURIComponent(this.matchId)}?as=${this.you}`);
    $("end-title").textContent = won + you;
    $("end-text").textContent = why[0].toUpperCase() + why.slice(1) + ".";
    $("end").hidden = false;
    $("hud-status").textContent = "";
  }

  legend() {
    const el = $("legend");
    if (!this.beliefOn || !this.belief) { el.replaceChildren(); return; }
    const rows = this.belief.roles.filter((r) => !r.tagged).map((r) => {
      const div = document.createElement("div");
      const dot = document.createElement("i");
      dot.style.background = roleColor(r.id);
      const trust = r.state ? ` · ${r.state} (${Number(r.confidence).toFixed(2)})` : "";
      div.append(dot, `role ${r.id}: ${r.count} opponent${r.count === 1 ? "" : "s"} · ${r.particles} particles${trust}`);
      return div;
    });
    const head = document.createElement("div");
    head.textContent = "robots' belief (B)";
    head.style.color = "#8b949e";
    el.replaceChildren(head, ...rows);
  }

  key(e) {
    const codes = ["KeyW", "KeyA", "KeyS", "KeyD", "ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", "Space"];
    if (e.code === "KeyB" && e.type === "keydown" && !e.repeat) {
      this.beliefOn = !this.beliefOn;
      debug.belief = this.beliefOn;
      this.send({ type: "belief", on: this.beliefOn });
      this.legend();
      return;
    }
    if (!codes.includes(e.code)) return;
    e.preventDefault();
    if (e.type === "keydown") this.keys.add(e.code); else this.keys.delete(e.code);
    // A tap shorter than a tick still fires.
    if (e.code === "Space" && e.type === "keydown") {
      this.tagLatch = true;
      // The shot is aimed at what is drawn now, not at the next input tick's frame.
      this.tagView = this.renderTick === null ? null : Math.max(0, Math.round(this.renderTick));
    }
  }

  /** The keys held now, as an input. */
  held() {
    const k = this.keys;
    const forward = (k.has("KeyW") || k.has("ArrowUp") ? 1 : 0) - (k.has("KeyS") || k.has("ArrowDown") ? 1 : 0);
    const turn = (k.has("KeyA") || k.has("ArrowLeft") ? 1 : 0) - (k.has("KeyD") || k.has("ArrowRight") ? 1 : 0);
    return { forward, turn, tag: k.has("Space") };
  }

  /** Sends one numbered input per 50 ms tick that is due (the server applies one per tick,
   * in order) and predicts it. Timers run late in a busy or hidden tab: a long gap starts
   * the ticks again rather than sending a burst. */
  inputTicks(now) {
    if (this.role !== "player" || !this.ws || this.ws.readyState !== WebSocket.OPEN) return;
    if (this.tickAt === null || now - this.tickAt > 500) this.tickAt = now - TICK_MS;
    while (now - this.tickAt >= TICK_MS) {
      this.tickAt += TICK_MS;
      const { forward, turn, tag } = this.held();
      this.seq += 1;
      // The tick whose robots are on screen: a shot is judged where they were drawn.
      let view = this.renderTick === null ? undefined : Math.max(0, Math.round(this.renderTick));
      if (this.tagLatch && this.tagView !== null && this.tagView !== undefined) view = this.tagView;
      this.send({ type: "input", seq: this.seq, forward, turn, tag: tag || this.tagLatch, view_tick: view });
      this.tagLatch = false;
      this.tagView = null;
      if (this.predictor) this.predictor.push(this.seq, forward, turn);
      debug.sent = this.seq;
    }
  }

  /** The world at render time: snapshots interpolated by tick, a late one bridged by
   * extrapolating from the last two for a moment. */
  interpolated(now) {
    const snaps = this.snaps;
    if (!snaps.length) return null;
    const latest = snaps[snaps.length - 1];
    const t = (now - this.offset) / TICK_MS - this.delayTicks;
    this.renderTick = Math.min(t, latest.tick);
    if (t >= latest.tick) {
      const prev = snaps.length > 1 ? snaps[snaps.length - 2] : null;
      const ahead = Math.min(t - latest.tick, MAX_EXTRAPOLATE_TICKS);
      if (!prev || ahead <= 0) return { snap: latest, robots: latest.robots, opponents: latest.opponents };
      // Beyond the newest snapshot: carry each agent on along its last step.
      return { snap: latest, ...this.lerp(prev, latest, 1 + ahead / (latest.tick - prev.tick)) };
    }
    let a = snaps[0], b = latest;
    for (let i = snaps.length - 1; i > 0; i--) {
      if (snaps[i - 1].tick <= t) { a = snaps[i - 1]; b = snaps[i]; break; }
    }
    if (t <= a.tick || a === b) {
      const s = t <= a.tick ? a : b;
      return { snap: s, robots: s.robots, opponents: s.opponents };
    }
    return { snap: b, ...this.lerp(a, b, (t - a.tick) / (b.tick - a.tick)) };
  }

  /** Agents of `b`, moved `f` of the way from where they were in `a` (f > 1 extrapolates). */
  lerp(a, b, f) {
    const move = (list0, list1) => list1.map((q) => {
      const p = list0.find((x) => x.id === q.id);
      if (!p || q.tagged) return q;
      return { ...q, x: p.x + (q.x - p.x) * f, y: p.y + (q.y - p.y) * f, theta: p.theta + angleDiff(p.theta, q.theta) * f };
    });
    return { robots: move(a.robots, b.robots), opponents: move(a.opponents, b.opponents) };
  }

  frame(now) {
    if (!this.map) return;
    const v = fit(this.canvas, this.map);
    const w = this.interpolated(now);
    const robots = w ? w.robots : [];
    const opponents = w ? [...w.opponents] : [];
    let visible = null;
    if (w && w.snap.view === "player") {
      this.inputTicks(now);
      let me = opponents.find((o) => o.id === this.you);
      // Our own disc where we predict it (drawn from the keys held this very frame).
      const { forward, turn } = this.held();
      const own = this.predictor && this.predictor.drawn(now, (now - this.tickAt) / TICK_MS, forward, turn);
      if (me && own) {
        const i = opponents.indexOf(me);
        me = { ...me, ...own };
        opponents.splice(i, 1, me);
      }
      // Where the player's own disc is drawn (what a latency measurement watches).
      if (me) debug.own = { x: me.x, y: me.y, theta: me.theta };
      if (me) visible = visibility(this.segs, me.x, me.y);
    }
    this.beams = this.beams.filter((b) => now - b.t0 < 450);
    const counts = draw(this.ctx, v, {
      map: this.map, segs: this.segs, you: this.you, robots, opponents, visible,
      belief: this.beliefOn ? this.belief : null, beams: this.beams, now,
    });
    debug.drawn = counts;
    debug.frames = (debug.frames || 0) + 1;
  }
}
