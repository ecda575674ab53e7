// Marks (what other games call pings): a player points a spot out to their own side, a robot
// seen there, a way to go, or a danger; each teammate sees it on the arena for 5 s with the
// marker's name, or at the screen's edge as an arrow when the spot is off screen, and hears a
// short sound. The server delivers a mark to the marker's side only (spectators as late as
// the rest) and records it, so replays draw it too (docs/api.md).
//
// The layer is DOM over the canvas, not pixels in it: a mark is text a screen reader can
// announce and a browser test can find (`#marks-layer .mark`).

const $ = (id) => document.getElementById(id);
const debug = (window.__lasertag = window.__lasertag || {});

/** How long a mark shows, and what a player may send: at most `LIMIT` in `WINDOW_MS`
 * (the server refuses the rest). */
export const MARK_SECONDS = 5;
export const LIMIT = 3;
export const WINDOW_MS = 5000;
/** Q without the pointer over the arena marks this far ahead of the player (metres). */
const AHEAD_M = 3;
/** Q marks a robot rather than a way to go when one is drawn this close to the spot. */
const NEAR_M = 1.5;
/** A touch held this long on the arena opens the picker there. */
const LONG_PRESS_MS = 500;

/** Each kind's words and glyph (its colour is in style.css, `.mark[data-kind=…]`). */
export const KINDS = {
  robot: { label: "robot", glyph: "◎", sound: "mark_robot" },
  go: { label: "go", glyph: "➤", sound: "mark_go" },
  danger: { label: "danger", glyph: "⚠", sound: "mark_danger" },
};

/** Who made mark event `e`: its `name` where the event carries the marker's agent as `by`
 * as well, else `by`. */
export function markerName(e) {
  return e.name || e.by;
}

/** World point (x, y) in CSS pixels of the canvas for frame `v` (render.js `fit`): a
 * turned frame (`v.rot`) runs its x down the screen and its y from right to left. */
export function toScreen(v, x, y) {
  return v.rot ? [v.width - v.y(y), v.x(x)] : [v.x(x), v.y(y)];
}

/** The world point under canvas pixel (sx, sy) of frame `v` on `map`. */
export function toWorld(v, map, sx, sy) {
  const [px, py] = v.rot ? [sy, v.width - sx] : [sx, sy];
  return [(px - v.ox) / v.s, map.height - (py - v.oy) / v.s];
}

/** The marks drawn over the arena (`#marks-layer`), one element per mark, placed each frame. */
export class MarkLayer {
  constructor() {
    this.el = $("marks-layer");
    this.el.replaceChildren();
    this.shown = new Map();
  }

  /** Places `marks` ([{id, by, kind, x, y, age}], age 0..1 of its time) for frame `v`:
   * at the spot, or as an arrow at the edge of the area clear of the HUD when the spot is
   * outside it. */
  render(v, marks) {
    if (!marks.length && !this.shown.size) {
      if (debug.marks && debug.marks.length) debug.marks = [];
      return;
    }
    const w = this.el.clientWidth, h = this.el.clientHeight;
    // The top HUD line and the bottom controls cover the canvas's edges.
    const box = { left: 12, top: 48, right: w - 12, bottom: h - 40 };
    const seen = new Set();
    const drawn = [];
    for (const m of marks) {
      seen.add(m.id);
      let el = this.shown.get(m.id);
      if (!el) {
        el = document.createElement("div");
        const k = KINDS[m.kind] || KINDS.go;
        el.className = "mark";
        el.dataset.kind = m.kind;
        el.dataset.by = m.by;
        el.innerHTML = `<span class="mark-arrow" aria-hidden="true">➜</span><span class="mark-icon" aria-hidden="true"></span><span class="mark-text"></span>`;
        el.querySelector(".mark-icon").textContent = k.glyph;
        el.querySelector(".mark-text").textContent = `${m.by}: ${k.label}`;
        this.el.append(el);
        this.shown.set(m.id, el);
      }
      const [sx, sy] = toScreen(v, m.x, m.y);
      const inside = sx >= box.left && sx <= box.right && sy >= box.top && sy <= box.bottom;
      el.classList.toggle("edge", !inside);
      el.style.opacity = String(m.age > 0.8 ? (1 - m.age) / 0.2 : 1);
      if (inside) {
        el.style.transform = `translate(${sx}px, ${sy}px)`;
        el.style.removeProperty("--angle");
      } else {
        // Where the line from the centre to the spot leaves the box, kept in by the pin's
        // own size and its arrow's: the arrow points on.
        const mx = el.offsetWidth / 2 + 30, my = 50;
        const inner = { left: box.left + mx, right: box.right - mx, top: box.top + my, bottom: box.bottom - my };
        const cx = (box.left + box.right) / 2, cy = (box.top + box.bottom) / 2;
        const dx = sx - cx, dy = sy - cy;
        const t = Math.min(
          dx ? Math.abs(((dx > 0 ? inner.right : inner.left) - cx) / dx) : Infinity,
          dy ? Math.abs(((dy > 0 ? inner.bottom : inner.top) - cy) / dy) : Infinity);
        el.style.transform = `translate(${cx + dx * t}px, ${cy + dy * t}px)`;
        el.style.setProperty("--angle", `${Math.atan2(dy, dx)}rad`);
      }
      drawn.push({ by: m.by, kind: m.kind, x: m.x, y: m.y, edge: !inside, sx: Math.round(sx), sy: Math.round(sy) });
    }
    for (const [id, el] of this.shown) {
      if (!seen.has(id)) { el.remove(); this.shown.delete(id); }
    }
    debug.marks = drawn;
  }

  clear() {
    this.el.replaceChildren();
    this.shown.clear();
    debug.marks = [];
  }
}

/** Marks in a live match: those received (and the player's own, shown at once), and a
 * player's ways to make one: Q, Shift+Q, the HUD's three buttons, a right click or a long
 * press on the arena (a picker there). */
export class LiveMarks {
  /** `game`: the page (its `send`, `map`, `name`, `team`, `sound`, and `spot()`: the player's
   * own agent and the other side's drawn now). */
  constructor(game) {
    this.game = game;
    this.layer = new MarkLayer();
    this.list = [];
    this.sent = [];
    this.seq = 0;
    this.pointer = null;
    this.canvas = $("arena");
    this.picker = $("mark-picker");
    this.announce = $("marks-announce");
    this.buttons = $("marks");
    this.note = $("marks-note");
    this.enabled = false;
    this.handlers = [];
    const on = (el, type, fn, opts) => { el.addEventListener(type, fn, opts); this.handlers.push([el, type, fn, opts]); };
    on(this.canvas, "pointermove", (e) => { this.pointer = [e.clientX, e.clientY]; this.cancelPress(e); });
    on(this.canvas, "pointerleave", () => { this.pointer = null; });
    on(this.canvas, "pointerdown", (e) => this.press(e));
    on(window, "pointerup", () => this.cancelPress());
    on(window, "pointercancel", () => this.cancelPress());
    on(this.canvas, "contextmenu", (e) => {
      e.preventDefault();
      if (this.enabled) this.openPicker(e.clientX, e.clientY);
    });
    for (const b of this.buttons.querySelectorAll("button[data-kind]")) {
      on(b, "click", () => { b.blur(); this.mark(b.dataset.kind, this.ahead()); });
    }
    for (const b of this.picker.querySelectorAll("button[data-kind]")) {
      on(b, "click", () => {
        const at = this.pickAt;
        this.closePicker();
        if (at) this.mark(b.dataset.kind, at);
      });
    }
    on(window, "pointerdown", (e) => {
      if (!this.picker.hidden && !this.picker.contains(e.target)) this.closePicker();
    }, true);
    this.timer = setInterval(() => this.showLimit(), 250);
    this.layer.clear();
    this.closePicker();
    this.buttons.hidden = true;
    this.announce.textContent = "";
  }

  /** A player may mark (spectators only see them). */
  enable(on) {
    this.enabled = on;
    this.buttons.hidden = !on;
    // Beside the touch controls when they show (game.js makes them before this).
    this.buttons.classList.toggle("by-touch", !$("touch").hidden);
    this.showLimit();
  }

  stop() {
    clearInterval(this.timer);
    clearTimeout(this.pressTimer);
    for (const [el, type, fn, opts] of this.handlers) el.removeEventListener(type, fn, opts);
    this.closePicker();
    this.layer.clear();
    this.buttons.hidden = true;
  }

  /** Q: the spot under the pointer (over the arena) or ahead; a robot when one is drawn near
   * it on an opponent's screen, else a way to go. Shift+Q: danger. True when it was Q. */
  key(e) {
    if (e.code === "Escape" && !this.picker.hidden) { this.closePicker(); return true; }
    if (e.code !== "KeyQ") return false;
    e.preventDefault();
    if (e.type !== "keydown" || e.repeat || !this.enabled) return true;
    const at = this.under() || this.ahead();
    if (!at) return true;
    const { others } = this.game.spot();
    const near = this.game.team === "opponents" &&
      others.some((a) => Math.hypot(a.x - at[0], a.y - at[1]) < NEAR_M);
    this.mark(e.shiftKey ? "danger" : near ? "robot" : "go", at);
    return true;
  }

  /** The world point under the mouse pointer, if it is over the map. */
  under() {
    if (!this.pointer || !this.game.view) return null;
    const r = this.canvas.getBoundingClientRect();
    return this.onMap(toWorld(this.game.view, this.game.map, this.pointer[0] - r.left, this.pointer[1] - r.top));
  }

  /** `AHEAD_M` ahead of the player's own agent, kept on the map. */
  ahead() {
    const { me } = this.game.spot();
    if (!me || !this.game.map) return null;
    const { width, height } = this.game.map;
    const x = me.x + Math.cos(me.theta) * AHEAD_M, y = me.y + Math.sin(me.theta) * AHEAD_M;
    return [Math.max(0.2, Math.min(width - 0.2, x)), Math.max(0.2, Math.min(height - 0.2, y))];
  }

  onMap([x, y]) {
    const m = this.game.map;
    return m && x >= 0 && y >= 0 && x <= m.width && y <= m.height ? [x, y] : null;
  }

  /** Marks in the last `WINDOW_MS`, and whether one more may go. */
  room(now = performance.now()) {
    this.sent = this.sent.filter((t) => now - t < WINDOW_MS);
    return LIMIT - this.sent.length;
  }

  /** Sends a mark of `kind` at `at` (world metres) and shows it at once (the server's echo,
   * if any, replaces it). */
  mark(kind, at) {
    if (!this.enabled || !at || !KINDS[kind]) return;
    if (this.room() <= 0) { this.showLimit(); return; }
    const [x, y] = at.map((c) => Math.round(c * 100) / 100);
    this.game.send({ type: "mark", x, y, kind });
    this.sent.push(performance.now());
    debug.marksSent = (debug.marksSent || 0) + 1;
    this.add({ by: this.game.name || "you", kind, x, y, own: true });
    this.showLimit();
  }

  /** A teammate's mark (`event` kind `mark`), or the echo of the player's own. */
  received(e) {
    const by = markerName(e);
    const own = this.list.find((m) => m.own && m.by === by && m.kind === e.mark &&
      Math.hypot(m.x - e.x, m.y - e.y) < 0.05 && performance.now() - m.at < 3000);
    if (own) { own.own = false; return; }
    debug.marksReceived = (debug.marksReceived || 0) + 1;
    this.add({ by, kind: e.mark, x: e.x, y: e.y });
  }

  add(m) {
    const k = KINDS[m.kind] || KINDS.go;
    this.list.push({ ...m, id: ++this.seq, at: performance.now() });
    this.game.sound.play(k.sound);
    // Said once, politely: the arena itself is a picture.
    this.announce.textContent = `${m.own ? "you" : m.by} marked ${k.label}`;
  }

  /** Places the marks still showing over frame `v`. */
  draw(v, now) {
    this.list = this.list.filter((m) => now - m.at < MARK_SECONDS * 1000);
    this.layer.render(v, this.list.map((m) => ({ ...m, age: (now - m.at) / (MARK_SECONDS * 1000) })));
  }

  /** The HUD's buttons greyed out, with how long to wait, while the limit is reached. */
  showLimit() {
    if (!this.enabled) return;
    const now = performance.now();
    const left = this.room(now);
    const full = left <= 0;
    for (const b of this.buttons.querySelectorAll("button[data-kind]")) b.disabled = full;
    for (const b of this.picker.querySelectorAll("button[data-kind]")) b.disabled = full;
    const wait = full ? Math.ceil((WINDOW_MS - (now - this.sent[0])) / 1000) : 0;
    const text = full ? `3 marks in 5 s: next in ${wait} s` : "";
    if (this.note.textContent !== text) this.note.textContent = text;
    debug.marksLeft = left;
  }

  /** A touch held still on the arena opens the picker where it is. */
  press(e) {
    if (!this.enabled || e.pointerType === "mouse") return;
    clearTimeout(this.pressTimer);
    this.pressAt = [e.clientX, e.clientY];
    this.pressTimer = setTimeout(() => {
      this.pressTimer = null;
      this.openPicker(...this.pressAt);
    }, LONG_PRESS_MS);
  }

  cancelPress(e) {
    if (!this.pressTimer) return;
    // A finger moving more than a little is not holding still.
    if (e && this.pressAt && Math.hypot(e.clientX - this.pressAt[0], e.clientY - this.pressAt[1]) < 10) return;
    clearTimeout(this.pressTimer);
    this.pressTimer = null;
  }

  openPicker(cx, cy) {
    const r = this.canvas.getBoundingClientRect();
    const at = this.game.view && this.onMap(toWorld(this.game.view, this.game.map, cx - r.left, cy - r.top));
    if (!at) return;
    this.pickAt = at;
    this.picker.hidden = false;
    const pw = this.picker.offsetWidth, ph = this.picker.offsetHeight;
    const left = Math.max(4, Math.min(window.innerWidth - pw - 4, cx - pw / 2));
    const top = Math.max(4, Math.min(window.innerHeight - ph - 4, cy - ph - 12));
    this.picker.style.left = `${left}px`;
    this.picker.style.top = `${top}px`;
    this.showLimit();
    const first = this.picker.querySelector("button:not(:disabled)");
    if (first) first.focus();
    debug.markPicker = true;
  }

  closePicker() {
    this.picker.hidden = true;
    this.pickAt = null;
    debug.markPicker = false;
  }
}

/** Marks in a replay, from its recorded events: each shows for its 5 s from its tick.
 * `visible(e)` says whether the view shows it (a player's view: their side's only). */
export class ReplayMarks {
  constructor(events, visible) {
    this.layer = new MarkLayer();
    this.visible = visible;
    this.marks = (events || []).filter((e) => e.kind === "mark")
      .map((e, i) => ({ id: i + 1, by: markerName(e), agent: e.by, kind: e.mark, x: e.x, y: e.y, tick: e.tick }));
  }

  /** Places the marks showing at `tick` (ticks at `hz`) over frame `v`. */
  draw(v, tick, hz) {
    const span = MARK_SECONDS * hz;
    const now = this.marks.filter((m) => tick >= m.tick && tick < m.tick + span && this.visible(m))
      .map((m) => ({ ...m, age: (tick - m.tick) / span }));
    this.layer.render(v, now);
  }

  stop() {
    this.layer.clear();
  }
}
