// A finished match played back (#/replay/<id>; `?pov=o0` for that player's own view, `t=83.5`
// to open paused at that moment, `belief=1` with the robots' belief): the
// replay socket (/ws/replays/<id>, docs/api.md; socket.js), the arena drawn by render.js exactly as a
// live match is, and the controls: play and pause, the speed, a timeline marked with the
// match's events, the robots' belief (B) and, from a player's view, a switch to everyone's.

import { segments, sight } from "./geometry.js";
import { laserFov, rules } from "./rules.js";
import { draw, fit } from "./render.js";
import { addBeam, between, copyLink, feedLine, fmtTime, legend, replayLink } from "./hud.js";
import { PageSocket, socketUrl } from "./socket.js";

const $ = (id) => document.getElementById(id);
const debug = (window.__lasertag = window.__lasertag || {});

export const SPEEDS = [0.25, 0.5, 1, 2, 4, 8];
/** The server carries out at most this many seeks a second (it says so in its first
 * message); a page scrubbing faster sends the latest position at that pace. */
const SEEK_MS = 100;
/** The events the timeline marks, and how each is described. */
const MARKED = {
  tag: (e) => `${e.by} tagged ${e.target}`,
  robot_tagged: (e) => `${e.by} froze ${e.target}`,
  role_split: (e) => `belief: role ${e.role} split from ${e.from}`,
  role_merge: (e) => `belief: role ${e.from} merged into ${e.role}`,
};

/** The least width of a timeline mark's button, in CSS pixels (WCAG 2.5.8's 24). */
const MARK_PX = 24;

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

export class Replay {
  /** `as`: the opponent whose view to show (or null); `full`: start with everyone's view
   * all the same (the switch goes back to the player's); `t`: seconds in, where the replay
   * opens paused (null: from the start, playing); `belief`: true or false to show the
   * robots' belief or not (null: as the view has it by default). */
  constructor({ id, as, full, t = null, belief = null, base = "" }) {
    this.id = id;
    // The node that played the match, in a fleet ("" for this page's own server).
    this.base = base;
    this.as = as || null;
    this.fogged = Boolean(this.as) && !full;
    this.canvas = $("arena");
    this.ctx = this.canvas.getContext("2d");
    this.latest = null;
    this.prev = null;
    this.belief = null;
    this.beliefOn = belief === null ? !this.fogged : belief;
    this.beliefChosen = belief !== null;
    this.beams = [];
    this.names = {};
    this.speed = 1;
    this.playing = true;
    this.ticks = 0;
    this.lastSeek = 0;
    // The tick a connection starts at: where the page is. A link to a moment opens there,
    // paused (see `welcome`).
    this.from = t === null ? 0 : Math.max(0, Math.round(t * 20));
    if (t !== null) this.resume = false;
    this.socket = new PageSocket(this, {
      url: () => {
        const q = new URLSearchParams({ format: "compact", tick: String(this.from), speed: String(this.speed) });
        if (this.fogged) q.set("as", this.as);
        return socketUrl(this.base, `/ws/replays/${encodeURIComponent(this.id)}?${q}`);
      },
      types: { replay: "welcome", snapshot: "snapshot", event: "event", replay_status: "status" },
    });
    Object.assign(debug, {
      page: "replay", replayId: id, view: this.fogged ? this.as : "full", connected: false,
      snapshots: 0, lastTick: null, drawn: null, feed: [], playing: null, speed: null,
      belief: this.beliefOn, ticks: null, markers: 0, errors: [],
    });
    $("feed").replaceChildren();
    $("legend").replaceChildren();
    $("end").hidden = true;
    $("hud-ping").textContent = "";
    $("hud-sound").hidden = true;
    $("hud-score").textContent = "";
    $("hud-timer").textContent = "";
    $("hud-match").textContent = "replay";
    $("hud-status").textContent = "loading the replay…";
    this.controls();
    this.onKey = (e) => this.key(e);
    window.addEventListener("keydown", this.onKey);
    const loop = (t) => { if (!this.stopped) { this.frame(t); requestAnimationFrame(loop); } };
    requestAnimationFrame(loop);
    this.load();
  }

  stop() {
    this.stopped = true;
    clearTimeout(this.seekTimer);
    window.removeEventListener("keydown", this.onKey);
    this.socket.close(1000, "left");
  }

  /** The replay's summary and events (for the timeline), then the socket. A match that has
   * just ended may take a moment to become a replay: a 404 is tried again a few times. */
  async load() {
    for (let attempt = 0; ; attempt++) {
      let r;
      try {
        r = await fetch(`${this.base}/api/replays/${encodeURIComponent(this.id)}`);
      } catch (e) {
        $("hud-status").textContent = `cannot reach the server: ${e.message}`;
        return;
      }
      if (this.stopped) return;
      if (r.ok) { this.detail = await r.json(); break; }
      if (r.status !== 404 || attempt >= 12) {
        const body = await r.json().catch(() => ({}));
        $("hud-status").textContent = body.error || `no replay ${this.id}`;
        debug.errors.push(body.error || String(r.status));
        return;
      }
      $("hud-status").textContent = "waiting for the replay…";
      await sleep(500);
      if (this.stopped) return;
    }
    for (const p of this.detail.events || []) {
      if (p.kind === "player_joined") this.names[p.robot || p.opponent] = p.name;
    }
    this.markers();
    this.connect(this.from);
  }

  connect(tick) {
    this.from = tick;
    this.socket.connect();
  }

  /** A close the page did not ask for: true when there is no coming back; otherwise the
   * next try starts where the page is. */
  lost(e) {
    if (this.stopped) return true;
    if (e.code === 1001) { $("hud-status").textContent = "the server is shutting down"; return true; }
    this.from = this.latest ? this.latest.tick : 0;
    return false;
  }

  send(obj) {
    this.socket.send(obj);
  }

  welcome(w) {
    this.map = w.map;
    this.segs = segments(w.map);
    this.ticks = w.ticks;
    this.tickHz = w.tick_hz;
    this.you = w.you;
    if (w.you && w.name) this.names[w.you] = w.name;
    if (!this.beliefChosen) this.beliefOn = w.belief;
    if (w.belief !== this.beliefOn) this.send({ type: "belief", on: this.beliefOn });
    // A reconnection (or a switch of view) carries on as the page was: paused stays paused.
    if (this.resume === false && w.playing) {
      this.send({ type: "pause" });
      this.send({ type: "seek", tick: w.tick });
    }
    this.resume = undefined;
    const tl = $("replay-timeline");
    tl.max = String(w.ticks);
    const who = this.as ? this.names[this.as] || this.as : null;
    $("hud-match").textContent = `${w.map.name} · replay · ${this.fogged ? `as ${who} saw it` : "full view"}`;
    $("hud-status").textContent = "";
    const view = $("replay-view");
    view.hidden = !this.as;
    view.textContent = this.fogged ? "full view" : `${who}'s view`;
    view.title = this.fogged ? "show everything: true positions, scans and belief" : `show only what ${who} saw`;
    Object.assign(debug, { ticks: w.ticks, view: w.view, belief: this.beliefOn });
    this.status({ tick: w.tick, playing: w.playing, speed: w.speed });
  }

  status(s) {
    this.playing = s.playing;
    this.speed = s.speed;
    debug.playing = s.playing;
    debug.speed = s.speed;
    const atEnd = !s.playing && s.tick >= this.ticks && this.ticks > 0;
    const play = $("replay-play");
    play.textContent = s.playing ? "❚❚" : atEnd ? "↻" : "▶";
    play.title = s.playing ? "pause (Space)" : atEnd ? "play again from the start (Space)" : "play (Space)";
    for (const b of $("replay-speeds").children) b.classList.toggle("on", Number(b.dataset.speed) === s.speed);
    $("hud-status").textContent = atEnd ? this.outcome() : "";
    if (!s.playing) this.address(s.tick);
  }

  /** How the match ended, for the status line at the end of the replay. */
  outcome() {
    const d = this.detail || {};
    const who = d.winner === "robots" ? "the robots won" : d.winner === "opponents" ? "the opponents won" : "nobody won";
    const why = d.reason ? ` (${d.reason.replace("_", " ")})` : "";
    return `end of the match: ${who}${why}`;
  }

  snapshot(s) {
    const now = performance.now();
    const last = this.latest;
    // Played forward: move from the last snapshot to this one. A seek jumps.
    const forward = last && s.tick > last.tick && s.tick - last.tick <= 16;
    this.prev = forward ? last : null;
    this.latest = s;
    this.arrived = now;
    this.span = Math.max(50, 50 / this.speed);
    if (!forward) {
      this.beams = [];
      $("feed").replaceChildren();
    }
    if (s.belief) this.belief = s.belief;
    for (const a of [...s.opponents, ...s.robots]) if (a.name) this.names[a.id] = a.name;
    debug.snapshots++;
    debug.lastTick = s.tick;
    debug.snapView = s.view;
    // The address follows the moment shown: at once after a jump (a seek, a mark), at most
    // once a second while it plays (browsers throttle a page that rewrites it faster).
    if (!forward || now - (this.addressAt || 0) >= 1000) {
      this.addressAt = now;
      this.address(s.tick);
    }
    const tl = $("replay-timeline");
    if (!this.dragging) tl.value = String(s.tick);
    this.clock(s.tick);
    const sc = s.score;
    $("hud-score").textContent = `robots tagged ${sc.tags}/${sc.opponents} opponents · opponents tagged robots ${sc.robot_tags}×`;
    this.legend();
  }

  clock(tick) {
    const hz = this.tickHz || 20;
    $("replay-time").textContent = `${fmtTime(tick / hz)} / ${fmtTime(this.ticks / hz)}`;
    $("hud-timer").textContent = fmtTime(tick / hz);
  }

  who(id) {
    return this.names[id] || id;
  }

  event(e) {
    if (e.kind === "shot") return addBeam(this.beams, e, this.latest, this.segs);
    const text = {
      tag: () => `${this.who(e.by)} tagged ${this.who(e.target)}`,
      robot_tagged: () => `${this.who(e.by)} tagged ${e.target} (frozen 10 s)`,
      role_split: () => `belief: role ${e.role} split from ${e.from}`,
      role_merge: () => `belief: role ${e.from} merged into ${e.role} (${e.count})`,
      player_joined: () => `${e.name} joined as ${e.robot || e.opponent}`,
      player_left: () => `${e.name} left`,
      finished: () => (e.winner ? `match over: ${e.winner} win` : `match over: ${e.reason.replace("_", " ")}`),
    }[e.kind];
    if (!text) return;
    const line = text();
    debug.feed.push({ kind: e.kind, text: line, seq: e.seq });
    if (debug.feed.length > 50) debug.feed.shift();
    feedLine(line, e.kind.startsWith("role") ? "role" : e.kind);
  }

  legend() {
    legend($("legend"), this.beliefOn ? this.belief : null, false);
  }

  /** The timeline's marks: tags, frozen robots, and the belief's splits and merges. Each
   * is a line on a button at least MARK_PX wide, so that a finger or a shaky hand hits it
   * (WCAG's target size); marks closer than that on the timeline as wide as it is now share
   * one button, which goes to the first of them and names them all. */
  markers() {
    const el = $("replay-markers");
    const ticks = this.detail.ticks || 1;
    const px = (el.clientWidth || 600) / ticks;
    const groups = [];
    for (const e of (this.detail.events || []).filter((x) => MARKED[x.kind])) {
      const last = groups[groups.length - 1];
      if (last && (e.tick - last[last.length - 1].tick) * px < MARK_PX) last.push(e);
      else groups.push([e]);
    }
    const pct = (tick) => (100 * tick) / ticks;
    const marks = groups.map((g) => {
      const first = g[0].tick, span = g[g.length - 1].tick - first;
      const m = document.createElement("button");
      m.className = "marker";
      m.style.left = `calc(${pct(first)}% - ${MARK_PX / 2}px)`;
      m.style.width = `calc(${pct(span)}% + ${MARK_PX}px)`;
      m.title = g.map((e) => `${fmtTime(e.tick / 20)} ${MARKED[e.kind](e)}`).join("\n");
      m.onclick = () => this.seek(first, true);
      const lines = Object.assign(document.createElement("span"), { className: "lines" });
      lines.append(...g.map((e) => Object.assign(document.createElement("i"), {
        className: e.kind, style: `left: ${span ? (100 * (e.tick - first)) / span : 0}%`,
      })));
      m.append(lines);
      return m;
    });
    el.replaceChildren(...marks);
    debug.markers = marks.length;
  }

  controls() {
    $("replay-play").onclick = () => this.toggle();
    $("replay-speeds").replaceChildren(...SPEEDS.map((v) => {
      const b = document.createElement("button");
      b.className = "secondary";
      b.dataset.speed = String(v);
      b.textContent = `${v}×`;
      b.onclick = () => this.send({ type: "speed", speed: v });
      return b;
    }));
    const tl = $("replay-timeline");
    tl.value = "0";
    tl.oninput = () => { this.clock(Number(tl.value)); this.seek(Number(tl.value)); };
    tl.onchange = () => this.seek(Number(tl.value), true);
    tl.onpointerdown = () => { this.dragging = true; };
    tl.onpointerup = () => { this.dragging = false; };
    const belief = $("replay-belief");
    belief.onclick = () => this.toggleBelief();
    belief.classList.toggle("on", this.beliefOn);
    $("replay-view").onclick = () => this.switchView();
    const share = $("replay-share");
    share.textContent = "copy link";
    share.onclick = () => {
      copyLink(this.link(), share);
      setTimeout(() => { share.textContent = "copy link"; }, 2000);
    };
    // A clicked button keeps no focus: Space is play and pause, not "press it again".
    $("replay-bar").onclick = (e) => { if (e.target.tagName === "BUTTON") e.target.blur(); };
  }

  toggle() {
    this.send({ type: this.playing ? "pause" : "play" });
  }

  /** The address of the moment shown (or of `at`, a tick), from this view, with the belief
   * as it is. */
  link(at) {
    const tick = at ?? (this.latest ? this.latest.tick : Number($("replay-timeline").value) || 0);
    return replayLink(this.id, {
      seconds: tick / (this.tickHz || 20), pov: this.fogged ? this.as : "full",
      belief: this.beliefOn, as: this.as,
    });
  }

  /** Keeps the address bar on the moment shown (`at`, a tick, or the latest snapshot's),
   * so that the address itself is the link; nothing before the first snapshot, which would
   * rewrite the link the page was opened with. */
  address(at) {
    if (at === undefined && !this.latest) return;
    const url = new URL(this.link(at));
    history.replaceState(null, "", url.hash);
    debug.address = url.hash;
  }

  /** Seeks to `tick`: at once when `now` or when the last seek is old enough, otherwise the
   * latest position goes when it is (the server would coalesce them anyway). */
  seek(tick, now) {
    this.pendingSeek = tick;
    const wait = this.lastSeek + SEEK_MS - performance.now();
    clearTimeout(this.seekTimer);
    const go = () => {
      this.lastSeek = performance.now();
      this.send({ type: "seek", tick: this.pendingSeek });
    };
    if (now || wait <= 0) go(); else this.seekTimer = setTimeout(go, wait);
  }

  toggleBelief() {
    this.beliefOn = !this.beliefOn;
    this.beliefChosen = true;
    debug.belief = this.beliefOn;
    $("replay-belief").classList.toggle("on", this.beliefOn);
    this.send({ type: "belief", on: this.beliefOn });
    this.legend();
    if (!this.playing) this.address();
  }

  /** From the player's view to everyone's and back, at the same tick, playing or paused as
   * it was. */
  switchView() {
    if (!this.as) return;
    this.fogged = !this.fogged;
    this.resume = this.playing;
    if (!this.beliefChosen) this.beliefOn = !this.fogged;
    $("replay-belief").classList.toggle("on", this.beliefOn);
    debug.view = this.fogged ? this.as : "full";
    this.address();
    this.socket.close(1000, "view");
    this.latest = null;
    this.prev = null;
    this.belief = null;
    this.connect(Number($("replay-timeline").value) || 0);
  }

  key(e) {
    if (e.target && e.target.tagName === "INPUT" && e.target.type !== "range") return;
    // The focused timeline moves itself with the arrows (and seeks through its input event).
    if (e.target && e.target.type === "range" && e.code.startsWith("Arrow")) return;
    if (e.repeat && e.code !== "ArrowLeft" && e.code !== "ArrowRight") return;
    const tick = this.latest ? this.latest.tick : 0;
    switch (e.code) {
      case "KeyB": this.toggleBelief(); break;
      case "Space": this.toggle(); break;
      case "ArrowLeft": this.seek(Math.max(0, tick - (e.shiftKey ? 20 : 1))); break;
      case "ArrowRight": this.seek(Math.min(this.ticks, tick + (e.shiftKey ? 20 : 1))); break;
      default: return;
    }
    e.preventDefault();
  }

  /** Agents between the last two snapshots: one step behind, so motion is smooth at any
   * speed (at 0.25× a snapshot comes every 200 ms). */
  agents(now) {
    const b = this.latest;
    const a = this.prev;
    if (!a) return { robots: b.robots, opponents: b.opponents };
    return between(a, b, Math.min(1, (now - this.arrived) / this.span));
  }

  frame(now) {
    if (!this.map || !this.latest) return;
    const v = fit(this.canvas, this.map);
    const { robots, opponents } = this.agents(now);
    let visible = null;
    if (this.latest.view === "player") {
      // A person on the robot team saw through their robot's laser.
      const robot = String(this.you).startsWith("r");
      const me = (robot ? robots : opponents).find((a) => a.id === this.you);
      const laser = robot ? { range: rules.laser.range, fov: laserFov } : null;
      if (me) visible = sight(this.segs, me, laser);
    }
    this.beams = this.beams.filter((b) => now - b.t0 < 450);
    const counts = draw(this.ctx, v, {
      map: this.map, segs: this.segs, you: this.latest.view === "player" ? this.you : null,
      robots, opponents, visible, belief: this.beliefOn ? this.belief : null, beams: this.beams, now,
    });
    debug.drawn = counts;
  }
}
