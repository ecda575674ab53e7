// The queue's waiting view (#/queue; docs/api.md, "Playing together"): how long this person
// has waited and how many are looking, pushed on the ticket's socket about every second,
// until the server has put a match together; then the seat, as a party's start gives one. In a
// fleet the queue is one node's (the server answers 307 there): the ticket, its socket and the
// match are on that node, which the page remembers as `base`.

import { GONE, LiveSocket, answer, call, seat } from "./party.js";
import { socketUrl } from "./socket.js";

const $ = (id) => document.getElementById(id);
const debug = (window.__lasertag = window.__lasertag || {});

/** The queue ticket this tab waits on: {ticket, token, base}. */
const QUEUE = "lasertag.queue";
/** Reconnections (waits of 0.25, 0.5, 1, 2 and 4 s) before a silent server counts as gone. */
const LOST_AFTER_TRIES = 5;

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
        const { data, from } = await answer("POST", "/api/queue", body);
        held = { ...data, base: from };
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
    const base = held.base || "";
    debug.queue = { ticket: held.ticket, base, seconds: 0, people: null };
    $("queue-status").textContent = "Looking for players…";
    this.socket = new LiveSocket({
      url: () => socketUrl(base, `/ws/queue/${encodeURIComponent(held.ticket)}?token=${encodeURIComponent(held.token)}`),
      onOpen: () => { $("queue-status").textContent = "Looking for players…"; },
      onMessage: (msg) => this.message(msg),
      onRetry: () => { $("queue-status").textContent = "reconnecting…"; },
      onClose: (code, tries) => {
        if (code === GONE) {
          this.lapsed("Your place in the queue lapsed.");
          return true;
        }
        // A ticket lives only while its server runs: one that has not answered for about
        // eight seconds (restarted, or a fleet's queue node gone) holds it no longer.
        if (tries >= LOST_AFTER_TRIES) {
          this.lapsed("The queue's server went away and your place with it.");
          return true;
        }
        return false;
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
      this.deps.playsOn(msg.match_id, this.held.base || "");
      $("queue-status").textContent = "Found a match: starting…";
      location.hash = seat(msg);
    } else if (msg.type === "error") {
      $("queue-error").textContent = msg.error;
    }
  }

  lapsed(why) {
    sessionStorage.removeItem(QUEUE);
    this.held = null;
    $("queue-status").textContent = "";
    $("queue-error").textContent = why;
    $("queue-cancel").hidden = true;
    $("queue-again").hidden = false;
    $("queue-again").focus();
  }

  leave(held) {
    sessionStorage.removeItem(QUEUE);
    return call("DELETE", `/api/queue/${encodeURIComponent(held.ticket)}`, null, held.token, held.base || "").catch(() => {});
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
