// A party's waiting room (#/party/<code>; docs/api.md, "Playing together"), and what it shares
// with the queue's view (queue.js): a socket the server pushes on, reconnected by itself with a
// growing wait (a restarted server keeps its parties, their tokens and the queue's tickets),
// and the seat a match gives, taken the way the lobby's doors take one: the seat token in
// sessionStorage, then #/play/<id>.

import { socketUrl } from "./socket.js";

const $ = (id) => document.getElementById(id);
const debug = (window.__lasertag = window.__lasertag || {});

/** This browser's memberships, by code: {code, member_id, member_token, match_id?, team?}. */
const PARTIES = "lasertag.parties";
const RETRY_FIRST_MS = 250;
const RETRY_MAX_MS = 5000;
const COUNTDOWN_S = 3;
/** Close codes the server gives a party's socket: the party is gone, or the member removed. */
export const GONE = 4404;
const REMOVED = 4403;
const SIDES = { opponents: "opponents", robots: "robots" };

/** The memberships this browser keeps. */
export const parties = {
  all() {
    try { return JSON.parse(localStorage.getItem(PARTIES) || "{}") || {}; } catch { return {}; }
  },
  get(code) { return this.all()[code] || null; },
  put(entry) {
    const all = this.all();
    all[entry.code] = entry;
    localStorage.setItem(PARTIES, JSON.stringify(all));
  },
  remove(code) {
    const all = this.all();
    delete all[code];
    localStorage.setItem(PARTIES, JSON.stringify(all));
  },
  /** The code of the party whose match `id` is, for the end card's *Again*. */
  ofMatch(id) {
    const hit = Object.values(this.all()).find((p) => p.match_id === id);
    return hit ? hit.code : null;
  },
};

/** `path`'s JSON answer; an Error with the server's message and `status` otherwise. */
export async function call(method, path, body, token, base = "") {
  return (await answer(method, path, body, token, base)).data;
}

/** `path` on the node at `base` ("" for this server): the JSON answer, and the origin that
 * gave it ("" for this server; in a fleet the queue is one node's, reached by following
 * the 307). */
export async function answer(method, path, body, token, base = "") {
  const headers = {};
  if (body) headers["content-type"] = "application/json";
  if (token) headers.authorization = `Bearer ${token}`;
  const r = await fetch(base + path, { method, headers, body: body ? JSON.stringify(body) : undefined });
  const text = await r.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch { /* not JSON: say the status */ }
  if (!r.ok) {
    const e = new Error(data && data.error ? data.error : `the server answered ${r.status}`);
    e.status = r.status;
    throw e;
  }
  const origin = new URL(r.url, location.href).origin;
  return { data, from: origin === location.origin ? "" : origin };
}

/** A party code as typed or linked: capitals, no spaces. */
export function normalCode(code) {
  return decodeURIComponent(code || "").replace(/[\s-]/g, "").toUpperCase();
}

/** The seat a `start` or `matched` message gives: kept where the play page looks for it
 * (app.js `tokenFor`), and the play page's address. */
export function seat(msg) {
  const robots = msg.team === "robots";
  sessionStorage.setItem(`lasertag.token.${msg.match_id}${robots ? ".robots" : ""}`, msg.token);
  return `#/play/${encodeURIComponent(msg.match_id)}${robots ? "?team=robots" : ""}`;
}

/** A socket to `url()` that comes back by itself after a close the page did not ask for
 * (waits doubling up to 5 s); `onClose(code)` is true when there is no coming back. */
export class LiveSocket {
  constructor({ url, onMessage, onOpen, onClose, onRetry }) {
    Object.assign(this, { url, onMessage, onOpen, onClose, onRetry });
    this.tries = 0;
    this.closed = false;
    this.connect();
  }

  connect() {
    if (this.closed) return;
    const ws = new WebSocket(this.url());
    this.ws = ws;
    ws.onopen = () => { this.tries = 0; this.onOpen(); };
    ws.onmessage = (m) => {
      let msg;
      try { msg = JSON.parse(m.data); } catch { return; }
      this.onMessage(msg);
    };
    ws.onclose = (e) => {
      if (this.closed || this.ws !== ws) return;
      if (this.onClose(e.code, this.tries)) return;
      const wait = Math.min(RETRY_FIRST_MS * 2 ** this.tries++, RETRY_MAX_MS);
      this.onRetry(wait);
      this.timer = setTimeout(() => this.connect(), wait);
    };
  }

  /** Closes the socket for good: one close frame however often the page asks. */
  close() {
    this.closed = true;
    clearTimeout(this.timer);
    const ws = this.ws;
    this.ws = null;
    if (ws) { ws.onclose = null; ws.close(1000, "left"); }
  }
}

/** The 3-2-1 over every member's page when the host starts, then `go()`. */
function countdown(go) {
  const box = $("countdown");
  const num = $("countdown-number");
  $("countdown-text").textContent = "The match starts";
  box.hidden = false;
  let n = COUNTDOWN_S;
  debug.countdown = n;
  num.textContent = String(n);
  const timer = setInterval(() => {
    n -= 1;
    debug.countdown = n;
    if (n > 0) { num.textContent = String(n); return; }
    clearInterval(timer);
    num.textContent = "Go!";
    setTimeout(() => { box.hidden = true; go(); }, 250);
  }, 1000);
  return () => { clearInterval(timer); box.hidden = true; };
}

/** Options of a <select> from [value, text] pairs, kept as they are when unchanged (a focused
 * select being rebuilt would lose its place). */
function fillSelect(sel, pairs) {
  const same = sel.options.length === pairs.length &&
    pairs.every(([v, t], i) => sel.options[i].value === v && sel.options[i].textContent === t);
  if (same) return;
  const value = sel.value;
  sel.replaceChildren(...pairs.map(([v, t]) => Object.assign(document.createElement("option"), { value: v, textContent: t })));
  if (pairs.some(([v]) => v === value)) sel.value = value;
}

/** The waiting room of party `code`. `deps`: the lobby's `playerName()` and `nameToken(name,
 * base)` (a kept name plays under its token). */
export class PartyRoom {
  constructor({ code, deps }) {
    this.code = normalCode(code);
    this.deps = deps;
    this.party = null;
    this.entry = parties.get(this.code);
    Object.assign(debug, {
      page: "party", partyCode: this.code, party: null, countdown: null,
      partyMember: this.entry?.member_id ?? null,
    });
    document.title = `Party ${this.code} · lasertag`;
    $("party-error").textContent = "";
    $("party-announce").textContent = "";
    $("party-copy-status").textContent = "";
    $("party-room").hidden = true;
    $("party-join").hidden = true;
    // Not ready until the room says otherwise (a room shown before may have left it pressed).
    $("party-ready").setAttribute("aria-pressed", "false");
    $("party-ready").classList.remove("on");
    this.wire();
    if (this.entry) this.enter(); else this.askName();
  }

  stop() {
    this.stopped = true;
    if (this.socket) this.socket.close();
    if (this.cancelCountdown) this.cancelCountdown();
  }

  /** No membership here yet: who is in, and a name to join under. */
  async askName() {
    $("party-join").hidden = false;
    $("party-join-code").textContent = this.code;
    const input = $("party-join-name");
    input.value = input.value || localStorage.getItem("lasertag.name") || "";
    input.focus();
    try {
      const p = await call("GET", `/api/parties/${this.code}`);
      if (this.stopped) return;
      const names = p.members.map((m) => m.name);
      $("party-join-who").textContent = `${names.length} in the room: ${names.join(", ")}.`;
    } catch (e) {
      if (this.stopped) return;
      this.failed(e);
    }
  }

  async join(e) {
    e.preventDefault();
    const name = $("party-join-name").value.trim();
    if (!name) return;
    $("name").value = name;
    $("party-join-button").disabled = true;
    $("party-error").textContent = "";
    try {
      const body = { name: this.deps.playerName() };
      const tok = await this.deps.nameToken(body.name, "");
      if (tok) body.name_token = tok;
      const m = await call("POST", `/api/parties/${this.code}/members`, body);
      this.entry = { code: this.code, member_id: m.member_id, member_token: m.member_token };
      debug.partyMember = m.member_id;
      parties.put(this.entry);
      $("party-join").hidden = true;
      this.enter();
    } catch (err) {
      this.failed(err);
    } finally {
      $("party-join-button").disabled = false;
    }
  }

  /** A refusal in the room's words. */
  failed(e) {
    const why = {
      404: `There is no party ${this.code}: check the code, or ask for a new link.`,
      409: e.message.includes("full") || !e.message ? "The party is full (8 people)." : e.message,
      429: "Too many tries in a short time: wait a moment and try again.",
    }[e.status] || e.message;
    $("party-error").textContent = why;
    debug.partyError = why;
  }

  /** In the room: its socket pushes the party on every change. */
  enter() {
    $("party-room").hidden = false;
    const link = `${location.origin}${location.pathname}#/party/${this.code}`;
    // Read out letter by letter; shown as one spaced word.
    const shown = Object.assign(document.createElement("span"), { textContent: this.code });
    shown.setAttribute("aria-hidden", "true");
    const spelled = Object.assign(document.createElement("span"), { className: "visually-hidden", textContent: this.code.split("").join(" ") });
    $("party-code").replaceChildren(shown, spelled);
    $("party-code").dataset.code = this.code;
    $("party-link").value = link;
    const qr = $("party-qr");
    qr.src = `/api/parties/${this.code}/invite.svg`;
    qr.alt = `QR code of the invite link ${link}: scan it with a phone to join`;
    this.conn("connecting…");
    this.loadChoices();
    this.socket = new LiveSocket({
      url: () => socketUrl("", `/ws/parties/${this.code}?token=${encodeURIComponent(this.entry.member_token)}`),
      onOpen: () => { this.conn(""); debug.partyConnected = true; },
      onMessage: (msg) => this.message(msg),
      onRetry: () => { debug.partyConnected = false; this.conn("reconnecting…"); },
      onClose: (code, tries) => this.closed(code, tries),
    });
  }

  conn(text) {
    $("party-conn").textContent = text;
    $("party-conn").hidden = !text;
  }

  /** True when the socket should not come back: the party is gone or this member removed.
   * A socket refused before it opens says no code; after a few, the party is looked up. */
  closed(code, tries) {
    if (code === GONE || code === REMOVED) { this.gone(code); return true; }
    if (tries === 3) {
      call("GET", `/api/parties/${this.code}`).then((p) => {
        if (!p.members.some((m) => m.id === this.entry.member_id)) this.gone(REMOVED);
      }, (e) => { if (e.status === 404) this.gone(GONE); });
    }
    return false;
  }

  gone(code) {
    if (this.stopped) return;
    if (this.socket) this.socket.close();
    parties.remove(this.code);
    $("party-room").hidden = true;
    const why = code === GONE
      ? `Party ${this.code} is over: nobody was in it for a while, or its host closed it.`
      : `You are no longer in party ${this.code}: the host removed you.`;
    $("party-error").textContent = why;
    debug.partyError = why;
    debug.partyGone = code;
  }

  message(msg) {
    if (msg.type === "party") this.show(msg);
    else if (msg.type === "start") this.start(msg);
    else if (msg.type === "error") $("party-error").textContent = msg.error;
  }

  /** A match started for this party: the member's seat, 3-2-1, and play. */
  start(msg) {
    if (this.cancelCountdown) return;
    this.entry = { ...this.entry, match_id: msg.match_id, team: msg.team || "opponents" };
    parties.put(this.entry);
    const to = seat(msg);
    debug.partyStart = { match_id: msg.match_id, team: msg.team };
    this.cancelCountdown = countdown(() => {
      this.cancelCountdown = null;
      if (!this.stopped) location.hash = to;
    });
  }

  /** The host's choices: the maps and robot teams the server offers. */
  async loadChoices() {
    try {
      const [maps, teams] = await Promise.all([call("GET", "/api/maps"), call("GET", "/api/difficulties")]);
      fillSelect($("party-map"), maps.map((m) => [m.name, `${m.name} (${m.width}×${m.height} m)`]));
      fillSelect($("party-difficulty"), teams.map((d) => [d.name, d.rating ? `${d.name} (rated ${Math.round(d.rating)})` : d.name]));
      this.choices = true;
      if (this.party) this.show(this.party, true);
    } catch { /* the settings show as text */ }
  }

  /** Sets this member's (or, as host, another's) fields; the push shows the outcome. */
  async patch(body, member = this.entry.member_id) {
    $("party-error").textContent = "";
    try {
      const p = await call("PATCH", `/api/parties/${this.code}/members/${encodeURIComponent(member)}`, body, this.entry.member_token);
      if (p && p.members) this.show(p);
    } catch (e) {
      this.failed(e);
    }
  }

  wire() {
    $("party-join").onsubmit = (e) => this.join(e);
    $("party-copy").onclick = () => this.copy();
    $("party-ready").onclick = () => {
      if (!this.entry) return;
      // The person changes what they see pressed, even before the room's first push that
      // holds them has come (just after joining), when `me()` is not there yet.
      const pressed = $("party-ready").getAttribute("aria-pressed") === "true";
      this.patch({ ready: !pressed });
    };
    $("party-side").onchange = (e) => this.patch({ side: e.target.value });
    const setting = (key, value) => this.patch({ settings: { [key]: value } });
    $("party-map").onchange = (e) => setting("map", e.target.value);
    $("party-difficulty").onchange = (e) => setting("difficulty", e.target.value);
    $("party-minutes").onchange = (e) => {
      const v = Math.round(Number(e.target.value));
      if (v >= 1 && v <= 10) setting("minutes", v);
    };
    $("party-settings").onsubmit = (e) => e.preventDefault();
    $("party-start").onclick = () => this.startMatch();
    $("party-leave").onclick = () => this.leave();
    $("party-rejoin").onclick = () => {
      const robots = this.entry.team === "robots";
      location.hash = `#/play/${encodeURIComponent(this.entry.match_id)}${robots ? "?team=robots" : ""}`;
    };
  }

  me() {
    return this.party && this.party.members.find((m) => m.id === this.entry.member_id);
  }

  isHost() {
    return Boolean(this.party) && this.party.host === this.entry.member_id;
  }

  async copy() {
    const link = $("party-link").value;
    const out = $("party-copy-status");
    debug.sharedLink = link;
    try {
      await navigator.clipboard.writeText(link);
      out.textContent = "Link copied.";
    } catch {
      // Where the page may not write the clipboard: the link selected, for Ctrl+C.
      const input = $("party-link");
      input.focus();
      input.select();
      let ok = false;
      try { ok = document.execCommand("copy"); } catch { /* selected all the same */ }
      out.textContent = ok ? "Link copied." : "Press Ctrl+C (⌘C) to copy the selected link.";
    }
    debug.copied = out.textContent;
  }

  async startMatch() {
    const btn = $("party-start");
    if (btn.getAttribute("aria-disabled") === "true") {
      // Focusable all the same, so a keyboard reaches it and hears why.
      $("party-announce").textContent = $("party-start-reason").textContent;
      return;
    }
    $("party-error").textContent = "";
    btn.setAttribute("aria-disabled", "true");
    try {
      await call("POST", `/api/parties/${this.code}/start`, {}, this.entry.member_token);
      $("party-start-reason").textContent = "Starting…";
    } catch (e) {
      $("party-error").textContent = e.status === 409 && e.message.startsWith("not ready")
        ? `Not everyone is ready: ${e.message.replace(/^not ready:\s*/, "")}.` : e.message;
      debug.partyError = $("party-error").textContent;
      if (this.party) this.show(this.party, true);
    }
  }

  async leave() {
    const me = this.entry;
    try {
      await call("DELETE", `/api/parties/${this.code}/members/${encodeURIComponent(me.member_id)}`, null, me.member_token);
    } catch (e) {
      if (e.status !== 404) { this.failed(e); return; }
    }
    if (this.socket) this.socket.close();
    parties.remove(this.code);
    location.hash = "#/";
  }

  async remove(member) {
    if (!confirm(`Remove ${member.name} from the party?`)) return;
    $("party-error").textContent = "";
    try {
      await call("DELETE", `/api/parties/${this.code}/members/${encodeURIComponent(member.id)}`, null, this.entry.member_token);
    } catch (e) {
      this.failed(e);
    }
  }

  /** What changed since the last push, in words for the live region. */
  changes(old, p) {
    if (!old) return "";
    const said = [];
    const before = new Map(old.members.map((m) => [m.id, m]));
    for (const m of p.members) {
      const was = before.get(m.id);
      if (!was) { said.push(`${m.name} joined`); continue; }
      if (was.ready !== m.ready) said.push(`${m.name} is ${m.ready ? "ready" : "not ready"}`);
      if (was.side !== m.side) said.push(`${m.name} plays on the ${m.side} side`);
      if (was.connected !== m.connected) said.push(`${m.name} ${m.connected ? "is connected" : "lost the connection"}`);
    }
    for (const m of old.members) if (!p.members.some((x) => x.id === m.id)) said.push(`${m.name} left`);
    const s0 = old.settings, s1 = p.settings;
    if (s0.map !== s1.map) said.push(`map: ${s1.map}`);
    if (s0.difficulty !== s1.difficulty) said.push(`robot team: ${s1.difficulty}`);
    if (s0.minutes !== s1.minutes) said.push(`${s1.minutes} minutes`);
    if (old.status !== p.status) said.push(p.status === "playing" ? "the match is on" : "back in the room");
    return said.join("; ");
  }

  /** Draws the room from party `p` (a push, or the GET's answer). */
  show(p, again = false) {
    if (p.type) { p = { ...p }; delete p.type; }
    const said = again ? "" : this.changes(this.party, p);
    this.party = p;
    debug.party = p;
    if (said) $("party-announce").textContent = `${said}.`;
    const me = this.me();
    const host = this.isHost();
    if (!me) return;
    this.members(p, host);
    const ready = $("party-ready");
    ready.setAttribute("aria-pressed", String(me.ready));
    ready.classList.toggle("on", me.ready);
    if (document.activeElement !== $("party-side")) $("party-side").value = me.side;
    this.settings(p, host);
    $("party-rated").textContent = p.rated
      ? "Rated: one person plays, so this match counts for a rating."
      : p.members.length > 1
        ? "Unrated: matches with more than one person do not change ratings."
        : "Unrated: only the robot team's own length, on the hunted side, counts for a rating.";
    $("party-rated").classList.toggle("rated", Boolean(p.rated));
    // Start: the host's, when everyone is ready.
    const start = $("party-start");
    start.hidden = !host;
    const waiting = p.members.filter((m) => !m.ready).map((m) => (m.id === me.id ? "you" : m.name));
    const playing = p.status === "playing";
    const blocked = playing || waiting.length > 0;
    start.setAttribute("aria-disabled", String(blocked));
    $("party-start-reason").textContent = playing
      ? "A match of this party is on: the room opens again when it ends."
      : waiting.length ? `${host ? "Start when" : "The host starts when"} everyone is ready; waiting for ${waiting.join(", ")}.`
        : host ? "Everyone is ready: start the match." : "Everyone is ready: the host starts the match.";
    const mine = playing && this.entry.match_id && this.entry.match_id === p.match_id;
    $("party-rejoin").hidden = !mine;
  }

  members(p, host) {
    const list = $("party-members");
    // A push while a control in the list has the focus: give it back after the redraw.
    const focused = list.contains(document.activeElement) ? document.activeElement.dataset.key : null;
    $("party-members-title").textContent = `Members (${p.members.length} of 8)`;
    list.replaceChildren(...p.members.map((m) => {
      const li = document.createElement("li");
      li.className = "member";
      li.dataset.memberId = m.id;
      Object.assign(li.dataset, { name: m.name, side: m.side, ready: String(m.ready), connected: String(m.connected) });
      const dot = document.createElement("span");
      dot.className = `dot ${m.connected ? "on" : "off"}`;
      dot.title = m.connected ? "connected" : "not connected";
      const dotText = Object.assign(document.createElement("span"), {
        className: "visually-hidden", textContent: m.connected ? "connected: " : "not connected: ",
      });
      const name = Object.assign(document.createElement("strong"), { className: "member-name", textContent: m.name });
      const tags = [];
      if (m.kept) tags.push(Object.assign(document.createElement("span"), { className: "kept", textContent: "✓ kept name", title: "a name this player keeps: rated and theirs only" }));
      if (m.id === p.host) tags.push(Object.assign(document.createElement("span"), { className: "badge host", textContent: "host" }));
      if (m.id === this.entry.member_id) tags.push(Object.assign(document.createElement("span"), { className: "you", textContent: "(you)" }));
      const who = document.createElement("span");
      who.className = "member-who";
      who.append(dot, dotText, name, ...tags);
      let side;
      if (host) {
        side = document.createElement("select");
        side.className = "member-side";
        side.dataset.key = `side-${m.id}`;
        side.setAttribute("aria-label", `side of ${m.name}`);
        fillSelect(side, Object.keys(SIDES).map((s) => [s, s]));
        side.value = m.side;
        side.onchange = () => this.patch({ side: side.value }, m.id);
      } else {
        side = Object.assign(document.createElement("span"), { className: "member-side", textContent: m.side });
      }
      side.dataset.side = m.side;
      const ready = Object.assign(document.createElement("span"), {
        className: `member-ready ${m.ready ? "ready" : "waiting"}`, textContent: m.ready ? "ready" : "not ready",
      });
      li.append(who, side, ready);
      if (host && m.id !== this.entry.member_id) {
        const rm = Object.assign(document.createElement("button"), { type: "button", className: "secondary member-remove", textContent: "Remove" });
        rm.dataset.key = `remove-${m.id}`;
        rm.setAttribute("aria-label", `Remove ${m.name}`);
        rm.onclick = () => this.remove(m);
        li.append(rm);
      }
      return li;
    }));
    if (focused) {
      const again = list.querySelector(`[data-key="${focused}"]`);
      if (again) again.focus();
    }
  }

  /** The settings: the host's controls, or as text for everyone else. */
  settings(p, host) {
    const s = p.settings;
    const form = $("party-settings");
    const view = $("party-settings-view");
    form.hidden = !host || !this.choices;
    view.hidden = !form.hidden;
    if (!form.hidden) {
      for (const [id, value] of [["party-map", s.map], ["party-difficulty", s.difficulty], ["party-minutes", s.minutes]]) {
        if (document.activeElement !== $(id)) $(id).value = String(value);
      }
    }
    const rows = [["Map", s.map], ["Robot team", s.difficulty], ["Minutes", String(s.minutes)]];
    view.replaceChildren(...rows.flatMap(([k, v]) => [
      Object.assign(document.createElement("dt"), { textContent: k }),
      Object.assign(document.createElement("dd"), { textContent: v }),
    ]));
  }
}

/** Creates a party with this browser's name (kept name token if any) as its host, and opens
 * its room. */
export async function createParty({ playerName, nameToken }) {
  const body = { name: playerName() };
  const tok = await nameToken(body.name, "");
  if (tok) body.name_token = tok;
  const p = await call("POST", "/api/parties", body);
  parties.put({ code: p.code, member_id: p.member_id, member_token: p.member_token });
  location.hash = `#/party/${p.code}`;
}
