// The queue's waiting view (#/queue; docs/api.md, "Playing together"): how long this person
// has waited and how many are looking, pushed on the ticket's socket about every second,
// until the server has put a match together; then the seat, as a party's start gives one.

import { GONE, LiveSocket, call, seat, wsUrl } from "./party.js";

const $ = (id) => document.getElementById(id);
const debug = (window.__lasertag = window.__lasertag || {});

/** The queue ticket this tab waits on: {ticket, token}. */
const QUEUE = "lasertag.queue";

/** The queue's waiting view: seconds waited, people looking, Cancel; a match found plays. */
export class QueueView {
  constructor({ deps }) {
    this.deps = deps;
    Object.assign(debug, { page: "queue", queue: null });
    document.title = "Finding players · lasertag";
    $("queue-error").textContent = "";
    $("queue-status").textContent = "";
    $("queue-seconds").textContent = "0 s";
    $("queue-people").textContent = "1";
    $("queue-cancel").hidden = false;
    $("queue-again").hidden = true;
    $("queue-cancel").onclick = () => this.cancel();
    $("queue-again").onclick = () => { $("queue-again").hidden = true; $("queue-cancel").hidden = false; this.enter(); };
    $("queue-cancel").focus();
    this.enter();
  }

  /** A ticket this tab holds (a reload waits on), or a new one. */
  async enter() {
    let held = null;
    try { held = JSON.parse(sessionStorage.getItem(QUEUE) || "null"); } catch { /* a new one */ }
    if (!held) {
      $("queue-status").textContent = "Joining the queue…";
      try {
        const body = { name: this.deps.playerName() };
        const tok = await this.deps.nameToken(body.name, "");
        if (tok) body.name_token = tok;
        held = await call("POST", "/api/queue", body);
      } catch (e) {
        if (this.stopped) return;
        $("queue-error").textContent = e.status === 429 ? "Too many tries in a short time: wait a moment and try again." : e.message;
        $("queue-status").textContent = "";
        $("queue-again").hidden = false;
        return;
      }
      if (this.stopped) { this.leave(held); return; }
      sessionStorage.setItem(QUEUE, JSON.stringify(held));
    }
    this.held = held;
    debug.queue = { ticket: held.ticket, seconds: 0, people: null };
    $("queue-status").textContent = "Looking for players…";
    this.socket = new LiveSocket({
      url: () => wsUrl(`/ws/queue/${encodeURIComponent(held.ticket)}?token=${encodeURIComponent(held.token)}`),
      onOpen: () => { $("queue-status").textContent = "Looking for players…"; },
      onMessage: (msg) => this.message(msg),
      onRetry: () => { $("queue-status").textContent = "reconnecting…"; },
      onClose: (code) => {
        if (code !== GONE) return false;
        this.lapsed();
        return true;
      },
    });
  }

  message(msg) {
    if (msg.type === "waiting") {
      $("queue-seconds").textContent = `${Math.floor(msg.seconds)} s`;
      $("queue-people").textContent = String(msg.people);
      Object.assign(debug.queue, { seconds: msg.seconds, people: msg.people });
    } else if (msg.type === "matched") {
      this.matched = true;
      sessionStorage.removeItem(QUEUE);
      this.socket.close();
      debug.queue.matched = msg.match_id;
      $("queue-status").textContent = "Found a match: starting…";
      location.hash = seat(msg);
    } else if (msg.type === "error") {
      $("queue-error").textContent = msg.error;
    }
  }

  lapsed() {
    sessionStorage.removeItem(QUEUE);
    this.held = null;
    $("queue-status").textContent = "";
    $("queue-error").textContent = "Your place in the queue lapsed.";
    $("queue-cancel").hidden = true;
    $("queue-again").hidden = false;
    $("queue-again").focus();
  }

  leave(held) {
    sessionStorage.removeItem(QUEUE);
    return call("DELETE", `/api/queue/${encodeURIComponent(held.ticket)}`, null, held.token).catch(() => {});
  }

  async cancel() {
    this.stopped = true;
    if (this.socket) this.socket.close();
    if (this.held) await this.leave(this.held);
    this.held = null;
    location.hash = "#/";
  }

  /** Leaving the page leaves the queue (a reload keeps the ticket: no `stop` runs). */
  stop() {
    this.stopped = true;
    if (this.socket) this.socket.close();
    if (this.held && !this.matched) this.leave(this.held);
  }
}
