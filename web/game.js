// One match in the browser: its WebSocket (socket.js), smooth motion between snapshots, the
// keyboard, the HUD (score, timer, ping, tag feed) and the end screen.

import { segments, sight } from "./geometry.js";
import { draw, fit } from "./render.js";
import { laserFov, rules } from "./rules.js";
import { addBeam, between, copyLink, feedLine, fmtTime, legend, replayLink } from "./hud.js";
import { Predictor } from "./predict.js";
import { PageSocket, socketUrl } from "./socket.js";
import { Sound } from "./sound.js";
import { TouchPad, touchScreen } from "./touch.js";
import { KINDS, LiveMarks, markerName } from "./marks.js";
import { keptNames, unkeptReason } from "./names.js";

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
/** Arrivals a connection needs before the HUD judges its link: the 95th percentile of
 * fewer is their worst one (a connection's first second, a server that just resumed the
 * match, says little of the link). */
const JITTER_SETTLED = 20;

/** What tests read: counts of what was drawn, the feed, the end. */
export const debug = (window.__lasertag = window.__lasertag || {});

/** The share of ticks, over the last few seconds, whose snapshot never came: a gap of a few
 * ticks between two snapshots (a longer one is a pause or a jump, not loss). */
class Missed {
  constructor() {
    this.last = null;
    this.window = []; // per snapshot: the ticks missed just before it
  }

  saw(tick) {
    const gap = this.last === null ? 1 : tick - this.last;
    this.last = tick;
    if (gap < 1) return;
    this.window.push(gap <= 10 ? gap - 1 : 0);
    if (this.window.length > 200) this.window.shift();
  }

  rate() {
    const missed = this.window.reduce((a, b) => a + b, 0);
    return this.window.length ? missed / (missed + this.window.length) : 0;
  }
}

export class Game {
  /** `onAgain`: the end card's *Again* for a party's match (back to its room). */
  constructor({ matchId, token, base = "", onLobby, onReplay, onStaleToken, onAgain = null }) {
    this.matchId = matchId;
    this.token = token;
    // The node that hosts the match, in a fleet ("" for this page's own server).
    this.base = base;
    this.onLobby = onLobby;
    this.onReplay = onReplay;
    this.onStaleToken = onStaleToken;
    this.onAgain = onAgain;
    this.welcomed = false;
    this.canvas = $("arena");
    this.ctx = this.canvas.getContext("2d");
    this.snaps = [];
    this.offset = null; // the steadiest recent arrival's time less its tick's (ms)
    this.arrivals = []; // recent arrivals' times less their ticks' (ms)
    this.delayTicks = MAX_DELAY_TICKS / 2;
    this.beams = [];
    this.missed = new Missed();
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
    Object.assign(debug, {
      page: "game", matchId, base, role: token ? "player" : "spectator", connected: false,
      snapshots: 0, lastTick: null, drawn: null, feed: [], ended: null, ping: null, you: null,
      belief: this.beliefOn, errors: [],
    });
    $("feed").replaceChildren();
    $("end").hidden = true;
    $("hud-sound").hidden = false;
    this.sound = new Sound($("hud-sound"));
    this.marks = new LiveMarks(this);
    this.inSight = 0;
    $("hud-status").textContent = "connecting…";
    // Closing the tab of a rated match one still plays counts as a loss: the browser asks
    // first (its own words; the HUD says why).
    this.onLeave = (e) => {
      if (this.role === "player" && this.team === "opponents" && this.rated && !this.ended && !this.tagged) {
        e.preventDefault();
        e.returnValue = "";
      }
    };
    window.addEventListener("beforeunload", this.onLeave);
    this.onKey = (e) => this.key(e);
    window.addEventListener("keydown", this.onKey);
    window.addEventListener("keyup", this.onKey);
    this.onBlur = () => { this.keys.clear(); };
    window.addEventListener("blur", this.onBlur);
    $("end-lobby").onclick = () => this.onLobby();
    $("end-replay").onclick = () => this.onReplay(this);
    // A party's match goes back to its room instead: the same people, the same sides.
    $("end-replay").hidden = Boolean(onAgain);
    $("end-again").hidden = !onAgain;
    $("end-again").onclick = () => this.onAgain();
    $("end-watch").hidden = true;
    // Snapshots in the compact binary form (see compact.js); the rest stays JSON text.
    const q = `?format=compact${token ? `&token=${encodeURIComponent(token)}` : ""}`;
    this.socket = new PageSocket(this, {
      url: () => socketUrl(base, `/ws/matches/${encodeURIComponent(matchId)}${q}`),
      types: { welcome: "welcome", snapshot: "snapshot", event: "event", finished: "finished", pong: "pong" },
    });
    this.socket.connect();
    this.pingTimer = setInterval(() => this.send({ type: "ping", t: performance.now() }), 1000);
    this.inputTimer = setInterval(() => this.inputTicks(performance.now()), 10);
    const loop = (t) => { if (!this.stopped) { this.frame(t); requestAnimationFrame(loop); } };
    requestAnimationFrame(loop);
  }

  stop() {
    this.stopped = true;
    clearInterval(this.pingTimer);
    clearInterval(this.inputTimer);
    window.removeEventListener("keydown", this.onKey);
    window.removeEventListener("keyup", this.onKey);
    window.removeEventListener("blur", this.onBlur);
    window.removeEventListener("beforeunload", this.onLeave);
    if (this.touch) this.touch.stop();
    this.marks.stop();
    this.socket.close(1000, "left");
  }

  /** A close the page did not ask for: true when there is no coming back. */
  lost(e) {
    if (this.stopped) return true;
    if (this.token && !this.welcomed && this.onStaleToken) {
      // Refused before the first message: the stored token's slot was freed. Join again.
      this.stop();
      this.onStaleToken();
      return true;
    }
    if (e.code === 1008) {
      $("hud-status").textContent = `disconnected: ${e.reason}`;
      return true;
    }
    // The match ended and was removed, or the server shut down: the end screen stays.
    return Boolean(this.ended) && (e.code === 1000 || e.code === 1001);
  }

  send(obj) {
    this.socket.send(obj);
  }

  pong(msg) {
    const rtt = performance.now() - msg.t;
    debug.ping = rtt;
    const jitter = debug.jitterMs || 0;
    // A hint a player can act on: what the round trip and the jitter will feel like, once
    // the connection has shown enough arrivals to say.
    const quality = this.arrivals.length < JITTER_SETTLED ? "measuring"
      : rtt < 120 && jitter < 40 ? "good" : rtt < 250 && jitter < 100 ? "fair" : "poor";
    // The carrier, and the share of ticks whose snapshot never came (datagrams lost; over
    // a WebSocket none is lost, only late).
    const transport = this.socket.transport === "webtransport" ? "WebTransport" : "WebSocket";
    const loss = this.missed.rate();
    debug.loss = loss;
    $("hud-ping").textContent = `ping ${rtt.toFixed(0)} ms · jitter ${jitter.toFixed(0)} ms · ${quality} · ${transport}` +
      (this.socket.transport === "webtransport" ? ` · loss ${(100 * loss).toFixed(1)}%` : "");
    $("hud-ping").dataset.quality = quality;
  }

  welcome(w) {
    this.welcomed = true;
    this.newConnection = true;
    // Jitter is one connection's: arrivals from before a reconnect, seconds older than the
    // outage was long, would read as seconds of it. The estimate and the time base start
    // over, and so does the count of snapshots missed (the outage lost none).
    this.arrivals = [];
    this.offset = null;
    this.missed = new Missed();
    debug.jitterMs = 0;
    debug.jitterResets = (debug.jitterResets || 0) + 1;
    this.map = w.map;
    this.segs = segments(w.map);
    this.you = w.you;
    this.role = w.role;
    this.name = w.name;
    // A person on the robot team drives a robot (`r1`): they hunt with the team's belief,
    // live, and see what its laser sees; an opponent's player is the hunted.
    this.team = w.team || (w.role === "player" ? "opponents" : null);
    debug.team = this.team;
    if (this.team === "robots" && !this.beliefSet) this.beliefOn = true;
    debug.belief = this.beliefOn;
    // A rated match rates only a name its player keeps (docs/ratings.md): one this browser
    // could not keep plays unrated, and the HUD says so from the start.
    const unkept = w.role === "player" && w.rated && !keptNames()[w.name]
      ? unkeptReason(w.name) || "your name is not kept on this server"
      : null;
    this.rated = Boolean(w.rated) && !unkept;
    debug.rated = this.rated;
    debug.unrated = unkept;
    this.tickHz = w.tick_hz;
    // A match people play is shown to spectators late (so that nobody can watch where the
    // robots are while playing them): say so, wherever the page shows everything.
    this.delay = w.spectator_delay_s > 0 ? `${Math.round(w.spectator_delay_s)} s behind` : "";
    debug.you = w.you;
    debug.role = w.role;
    debug.delay = w.spectator_delay_s;
    // A delayed match younger than its delay has only its first frame to show yet: say when
    // it starts to move rather than leave a still picture.
    this.viewStartsAt = w.view_starts_in_s > 0 ? performance.now() + w.view_starts_in_s * 1000 : null;
    debug.viewStartsIn = w.view_starts_in_s || 0;
    if (w.belief !== this.beliefOn) this.send({ type: "belief", on: this.beliefOn });
    // A (re)connection numbers its inputs from 1 again, and predicts only as a player.
    this.seq = 0;
    this.tickAt = null;
    // (`localStorage["lasertag.predict"] = "off"` turns prediction off, to measure what it buys.)
    const predict = w.role === "player" && w.kinematics && localStorage.getItem("lasertag.predict") !== "off";
    this.predictor = predict ? new Predictor(w.map, this.segs, w.kinematics) : null;
    const watching = this.delay ? `spectating, delayed ${this.delay}` : "spectating";
    const playing = this.team === "robots" ? `hunting as robot ${w.you} (${w.name})` : `playing ${w.you} (${w.name})`;
    const rated = this.team !== "opponents" ? ""
      : this.rated ? " · rated: leaving before the end counts as a loss"
        : unkept ? ` · unrated: ${unkept}` : "";
    $("hud-match").textContent = `${w.map.name} · ${w.role === "player" ? playing + rated : watching}`;
    $("hud-status").textContent = "";
    // On a touch screen a player drives with a stick and a tag button instead of keys.
    if (w.role === "player" && !this.touch && touchScreen()) {
      this.touch = new TouchPad({ onTag: () => this.fireTag() });
    }
    debug.touch = Boolean(this.touch);
    // The sounds are a player's (what happens to you); a spectator has no use for the switch.
    $("hud-sound").hidden = w.role !== "player";
    $("controls").hidden = Boolean(this.touch);
    // Marks are a player's, for their own side; spectators see them as late as the rest.
    this.marks.enable(w.role === "player");
    $("controls").innerHTML = w.role === "player"
      ? `<kbd>W</kbd><kbd>A</kbd><kbd>S</kbd><kbd>D</kbd> / arrows move and turn · <kbd>Space</kbd> tag · <kbd>Q</kbd> mark · <kbd>Shift</kbd>+<kbd>Q</kbd> danger · <kbd>B</kbd> ${this.team === "robots" ? "your team's" : "robots'"} belief · <kbd>M</kbd> sound`
      : `spectating${this.delay ? ` (${this.delay}: a match people can play is shown late)` : ""}: true positions, scans, goals and belief · <kbd>B</kbd> belief on/off`;
  }

  snapshot(s) {
    // A tick already passed on this connection: over WebTransport a large snapshot comes
    // twice, its motion as a datagram and the whole (scans, belief) on the stream, which
    // may come after later ticks' datagrams when a loss holds it up. The decoder has kept
    // its scans; the belief is taken here. (A connection's ticks only go on; a new one,
    // to a server that resumed the match, may start earlier: see below.)
    const newest = this.snaps.length ? this.snaps[this.snaps.length - 1].tick : null;
    if (!this.newConnection && newest !== null && s.tick <= newest) {
      if (s.belief) this.belief = s.belief;
      debug.late = (debug.late || 0) + 1;
      return;
    }
    this.newConnection = false;
    const now = performance.now();
    const sample = now - s.tick * TICK_MS;
    if (this.snaps.length && s.tick < this.snaps[this.snaps.length - 1].tick) {
      // Time went back (a reconnect to a server that resumed the match from its record):
      // start over.
      debug.clockWentBack = (debug.clockWentBack || 0) + 1;
      this.snaps = [];
      this.offset = null;
      this.arrivals = [];
    }
    // Jitter is how much later than the steadiest arrival of the last few seconds the
    // arrivals come (their 95th percentile against their minimum), measured within the
    // window only: a stream that stood still and then started (a delayed view before its
    // delay was over, a paused tab) is a schedule, not the network, and leaves the window.
    this.arrivals.push(sample);
    if (this.arrivals.length > JITTER_WINDOW) this.arrivals.shift();
    const sorted = [...this.arrivals].sort((a, b) => a - b);
    // Draw as late as 95% of arrivals need, so interpolation seldom runs out of snapshots.
    const jitter = sorted[Math.floor(0.95 * (sorted.length - 1))] - sorted[0];
    // The time base follows the earliest arrivals, drifting up slowly, and never lags the
    // window's earliest (after a schedule's jump it catches up within the window).
    this.offset = this.offset === null ? sample : Math.max(Math.min(this.offset + 0.5, sample), sorted[0]);
    this.delayTicks = Math.max(MIN_DELAY_TICKS, Math.min(MAX_DELAY_TICKS, (jitter + MARGIN_MS) / TICK_MS));
    debug.jitterMs = jitter;
    debug.delayMs = this.delayTicks * TICK_MS;
    this.missed.saw(s.tick);
    this.snaps.push(s);
    if (this.snaps.length > 12) this.snaps.shift();
    if (s.belief) {
      this.belief = s.belief;
      debug.beliefRoles = s.belief.roles.length;
    }
    if (this.predictor && s.view === "player" && s.ack !== undefined) {
      const me = this.mine(s);
      const others = [...s.robots, ...s.opponents].filter((a) => a !== me && !a.tagged).map((a) => [a.x, a.y]);
      if (me) this.predictor.reconcile(me, s.ack, others);
      debug.ack = s.ack;
      debug.corrections = this.predictor.corrections;
    } else if (s.view === "teammates" || (s.view === "spectator" && this.role === "player")) {
      this.predictor = null; // tagged: nothing of ours moves any more
      this.tagged = true; // and the keys drive nothing: no more inputs
    }
    // A player's snapshot holds only the other side's agents in its sight: one more is one
    // come into view.
    if (s.view === "player") {
      const inSight = this.team === "robots" ? s.opponents.length : s.robots.length;
      if (inSight > this.inSight) this.sound.play("seen");
      this.inSight = inSight;
    }
    for (const a of [...s.opponents, ...s.robots]) if (a.name) this.names[a.id] = a.name;
    debug.snapshots++;
    debug.lastTick = s.tick;
    debug.view = s.view;
    const sc = s.score;
    $("hud-score").textContent =
      `robots tagged ${sc.tags}/${sc.opponents} opponents · opponents tagged robots ${sc.robot_tags}×`;
    $("hud-timer").textContent = fmtTime(s.time_left_s);
    if (this.role === "player" && s.view === "teammates" && !this.ended) {
      $("hud-status").textContent = "you were tagged — watching through your teammates' eyes";
    }
    this.legend();
  }

  /** Where marks are made from: the player's own agent as drawn, and the other side's agents
   * drawn now. */
  spot() {
    return { me: this.me || null, others: this.others || [] };
  }

  /** This player's own agent in snapshot `s`: a robot or an opponent. */
  mine(s) {
    return (this.team === "robots" ? s.robots : s.opponents).find((a) => a.id === this.you);
  }

  who(id) {
    return this.names[id] ? `${this.names[id]}` : id;
  }

  event(e) {
    const latest = this.snaps[this.snaps.length - 1];
    let text = null;
    let cls = e.kind;
    switch (e.kind) {
      case "shot": addBeam(this.beams, e, latest, this.segs); break;
      case "tag":
        text = `${e.by === this.you ? "you" : this.who(e.by)} tagged ${e.target === this.you ? "you" : this.who(e.target)}`;
        if (e.target === this.you) this.sound.play("tagged");
        if (e.by === this.you) this.sound.play("tag");
        break;
      case "robot_tagged":
        text = `${e.by === this.you ? "you" : this.who(e.by)} tagged ${e.target === this.you ? "you" : this.who(e.target)} (frozen 10 s)`;
        if (e.by === this.you) this.sound.play("tag");
        if (e.target === this.you) this.sound.play("tagged");
        break;
      case "role_split": text = `belief: role ${e.role} split from ${e.from}`; cls = "role"; break;
      case "role_merge": text = `belief: role ${e.from} merged into ${e.role} (${e.count})`; cls = "role"; break;
      case "player_joined": {
        const as = e.robot || e.opponent;
        text = e.robot ? `${e.name} joined the robot team as ${as}` : `${e.name} joined as ${as}`;
        this.names[as] = e.name;
        break;
      }
      case "player_left": text = `${e.name} left`; break;
      case "mark": {
        this.marks.received(e);
        const k = KINDS[e.mark];
        const by = markerName(e);
        text = `${by === this.name ? "you" : by} marked ${k ? k.label : e.mark}`;
        break;
      }
      case "finished":
        text = e.winner ? `match over: ${e.winner} win` : `match over: ${e.reason.replace("_", " ")}`;
        break;
    }
    if (!text) return;
    debug.feed.push({ kind: e.kind, text, seq: e.seq });
    feedLine(text, cls);
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
      you = f.winner === (this.team === "robots" ? "robots" : "opponents") ? " — you win!" : " — you lose.";
    }
    // The replay from this player's own view: how the robots found it (see replay.js).
    const watch = $("end-watch");
    watch.hidden = this.role !== "player" || !this.you;
    watch.onclick = () => (location.hash = `#/replay/${encodeURIComponent(this.matchId)}?pov=${this.you}`);
    // The replay's last moment, from this page's point of view.
    const share = $("end-share");
    share.textContent = "Copy replay link";
    share.onclick = () => copyLink(replayLink(this.matchId, {
      seconds: f.time_s, pov: this.role === "player" ? this.you : "full", belief: this.beliefOn,
    }), share);
    $("end-title").textContent = won + you;
    // Keyboard users land on the card's first button rather than behind the overlay.
    requestAnimationFrame(() => {
      const first = [...$("end").querySelectorAll("button")].find((b) => !b.hidden);
      if (first && !this.stopped) first.focus();
    });
    $("end-text").textContent = why[0].toUpperCase() + why.slice(1) + ".";
    $("end-rating").textContent = "";
    if (this.role === "player" && this.rated && this.name) this.showRating(["all_tagged", "time_limit"].includes(f.reason));
    $("end").hidden = false;
    $("hud-status").textContent = "";
  }

  /** The player's rating change this match, once the history has it (it rates the match a
   * moment after the end); `counts` is false for an end that rates nobody. */
  async showRating(counts) {
    const out = $("end-rating");
    if (!counts) {
      out.textContent = "This rated match ended early: it does not change your rating.";
      return;
    }
    out.textContent = "Rating: …";
    for (let i = 0; i < 20 && this.ended; i++) {
      try {
        const r = await fetch(`${this.base}/api/players/${encodeURIComponent(this.name)}`);
        if (r.ok) {
          const p = await r.json();
          const m = (p.recent || []).find((x) => x.id === this.matchId);
          if (m && m.rating_after != null) {
            const change = Math.round(m.rating_after - m.rating_before);
            const dev = p.rating ? ` ± ${Math.round(2 * p.rating.deviation)}` : "";
            out.textContent = `Rating ${Math.round(m.rating_before)} → ${Math.round(m.rating_after)}` +
              ` (${change >= 0 ? "+" : ""}${change})${dev}`;
            out.className = change >= 0 ? "rating up" : "rating down";
            debug.ratingChange = { before: m.rating_before, after: m.rating_after };
            return;
          }
        }
      } catch { /* try again */ }
      await new Promise((ok) => setTimeout(ok, 500));
    }
    out.textContent = "Your rating will show on the leaderboard.";
  }

  legend() {
    // A hunter's is their team's, live; an opponent's player sees the robots' as late as
    // spectators do.
    const title = this.team === "robots" ? "your team's belief (B)"
      : this.role === "player" && this.delay ? `robots' belief, ${this.delay} (B)` : "robots' belief (B)";
    legend($("legend"), this.beliefOn ? this.belief : null, true, title);
  }

  key(e) {
    if (this.marks.key(e)) return;
    const codes = ["KeyW", "KeyA", "KeyS", "KeyD", "ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", "Space"];
    if (e.code === "KeyM" && e.type === "keydown" && !e.repeat) {
      this.sound.toggle();
      return;
    }
    if (e.code === "KeyB" && e.type === "keydown" && !e.repeat) {
      this.beliefOn = !this.beliefOn;
      this.beliefSet = true;
      debug.belief = this.beliefOn;
      this.send({ type: "belief", on: this.beliefOn });
      this.legend();
      return;
    }
    if (!codes.includes(e.code)) return;
    // A focused button (the HUD's) is not pressed again by Space: Space is the tag.
    if (e.target && e.target.tagName === "BUTTON" && e.code === "Space") e.target.blur();
    e.preventDefault();
    if (e.type === "keydown") this.keys.add(e.code); else this.keys.delete(e.code);
    if (e.code === "Space" && e.type === "keydown") this.fireTag();
  }

  /** A press of the trigger (Space, the touch tag button): a tap shorter than a tick still
   * fires. */
  fireTag() {
    this.tagLatch = true;
    // The shot is aimed at what is drawn now, not at the next input tick's frame.
    this.tagView = this.renderTick === null ? null : Math.max(0, Math.round(this.renderTick));
  }

  /** The keys held now, as an input. */
  held() {
    const k = this.keys;
    const forward = (k.has("KeyW") || k.has("ArrowUp") ? 1 : 0) - (k.has("KeyS") || k.has("ArrowDown") ? 1 : 0);
    const turn = (k.has("KeyA") || k.has("ArrowLeft") ? 1 : 0) - (k.has("KeyD") || k.has("ArrowRight") ? 1 : 0);
    // The touch stick adds to the keys (either alone drives fully).
    const t = this.touch || { forward: 0, turn: 0 };
    const clamp = (v) => Math.max(-1, Math.min(1, v));
    return { forward: clamp(forward + t.forward), turn: clamp(turn + t.turn), tag: k.has("Space") };
  }

  /** Sends one numbered input per 50 ms tick that is due (the server applies one per tick,
   * in order) and predicts it. Timers run late in a busy or hidden tab: a long gap starts
   * the ticks again rather than sending a burst. */
  inputTicks(now) {
    if (this.role !== "player" || this.tagged || !this.socket.open) return;
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
    if (this.offset === null) {
      // A new connection has no time base until its first snapshot: the last one stays.
      this.renderTick = latest.tick;
      return { snap: latest, robots: latest.robots, opponents: latest.opponents };
    }
    const t = (now - this.offset) / TICK_MS - this.delayTicks;
    this.renderTick = Math.min(t, latest.tick);
    if (t >= latest.tick) {
      const prev = snaps.length > 1 ? snaps[snaps.length - 2] : null;
      const ahead = Math.min(t - latest.tick, MAX_EXTRAPOLATE_TICKS);
      if (!prev || ahead <= 0) return { snap: latest, robots: latest.robots, opponents: latest.opponents };
      // Beyond the newest snapshot: carry each agent on along its last step.
      return { snap: latest, ...between(prev, latest, 1 + ahead / (latest.tick - prev.tick)) };
    }
    let a = snaps[0], b = latest;
    for (let i = snaps.length - 1; i > 0; i--) {
      if (snaps[i - 1].tick <= t) { a = snaps[i - 1]; b = snaps[i]; break; }
    }
    if (t <= a.tick || a === b) {
      const s = t <= a.tick ? a : b;
      return { snap: s, robots: s.robots, opponents: s.opponents };
    }
    return { snap: b, ...between(a, b, (t - a.tick) / (b.tick - a.tick)) };
  }

  /** Over a delayed view that has not started yet: when it will. */
  countdown(now) {
    if (this.viewStartsAt === null || this.viewStartsAt === undefined) return;
    const latest = this.snaps[this.snaps.length - 1];
    if (latest && latest.tick > 0) {
      this.viewStartsAt = null;
      $("hud-status").textContent = "";
      return;
    }
    const left = Math.max(0, Math.ceil((this.viewStartsAt - now) / 1000));
    $("hud-status").textContent =
      `people can play this match, so spectators see it ${this.delay}: it starts to move in ${left} s (everyone at their starts until then)`;
  }

  frame(now) {
    if (!this.map) return;
    const v = fit(this.canvas, this.map);
    const w = this.interpolated(now);
    const robots = w ? w.robots : [];
    const opponents = w ? [...w.opponents] : [];
    let visible = null;
    let robotsDrawn = robots;
    if (w && w.snap.view === "player") {
      this.inputTicks(now);
      const team = this.team === "robots" ? (robotsDrawn = [...robots]) : opponents;
      let me = team.find((a) => a.id === this.you);
      // Our own disc where we predict it (drawn from the keys held this very frame).
      const { forward, turn } = this.held();
      // (A frozen robot does not move, whatever the keys say.)
      const own = this.predictor && !(me && me.frozen) &&
        this.predictor.drawn(now, (now - this.tickAt) / TICK_MS, forward, turn);
      if (me && own) {
        const i = team.indexOf(me);
        me = { ...me, ...own };
        team.splice(i, 1, me);
      }
      // Where the player's own disc is drawn (what a latency measurement watches).
      if (me) debug.own = { x: me.x, y: me.y, theta: me.theta };
      // A robot sees what its laser sees; an opponent, what is in its line of sight.
      const laser = this.team === "robots" ? { range: rules.laser.range, fov: laserFov } : null;
      if (me) visible = sight(this.segs, me, laser);
      this.me = me;
      this.others = this.team === "robots" ? opponents : robots;
    }
    this.countdown(now);
    this.beams = this.beams.filter((b) => now - b.t0 < 450);
    const counts = draw(this.ctx, v, {
      map: this.map, segs: this.segs, you: this.you, robots: robotsDrawn, opponents, visible,
      belief: this.beliefOn ? this.belief : null, beams: this.beams, now,
    });
    debug.drawn = counts;
    this.view = v;
    this.marks.draw(v, now);
    debug.fit = { rot: v.rot, s: v.s };
    debug.drawnAgents = [...robotsDrawn, ...opponents].map((a) => [a.id, +a.x.toFixed(2), +a.y.toFixed(2)]);
    debug.frames = (debug.frames || 0) + 1;
  }
}
