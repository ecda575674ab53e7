// What the live page (game.js) and the replay page (replay.js) show alike around the
// arena: times as m:ss, the legend of the robots' belief, the tag feed, a shot's laser beam,
// agents moved between two snapshots, and links to a replay's moment.

import { castRay, angleDiff } from "./geometry.js";
import { roleColor } from "./render.js";
import { rules } from "./rules.js";

/** Beams drawn at once, at the most; lines in the feed. */
const MAX_BEAMS = 20;
const FEED_LINES = 8;

/** `s` seconds as m:ss. */
export function fmtTime(s) {
  s = Math.max(0, Math.floor(s));
  return `${Math.floor(s / 60)}:${String(s % 60).padStart(2, "0")}`;
}

/** The legend of `belief` in `el` (emptied without one): each role's count, its particles
 * when `particles`, and how far it is trusted; `title` heads it. */
export function legend(el, belief, particles, title = "robots' belief (B)") {
  if (!belief) { el.replaceChildren(); return; }
  const rows = belief.roles.filter((r) => !r.tagged).map((r) => {
    const div = document.createElement("div");
    const dot = document.createElement("i");
    dot.style.background = roleColor(r.id);
    const trust = r.state ? ` · ${r.state} (${Number(r.confidence).toFixed(2)})` : "";
    const held = particles ? ` · ${r.particles} particles` : "";
    div.append(dot, `role ${r.id}: ${r.count} opponent${r.count === 1 ? "" : "s"}${held}${trust}`);
    return div;
  });
  const head = document.createElement("div");
  head.textContent = title;
  head.style.color = "#8b949e";
  el.replaceChildren(head, ...rows);
}

/** A line on top of the feed (`#feed`), the oldest past its length dropped. */
export function feedLine(text, cls) {
  const li = document.createElement("li");
  li.className = cls;
  li.textContent = text;
  const feed = document.getElementById("feed");
  feed.prepend(li);
  while (feed.children.length > FEED_LINES) feed.lastChild.remove();
}

/** Adds to `beams` the laser of shot `e` as `snap` shows it: from the shooter to what it
 * hit, or along its heading to the first wall (the tag's range at the most); nothing when the shooter
 * is out of sight. */
export function addBeam(beams, e, snap, segs) {
  if (!snap) return;
  // A player hears of shots out of its sight late: the shooter has moved on since.
  if (snap.tick - e.tick > 2) return;
  const all = [...snap.robots, ...snap.opponents];
  const from = all.find((a) => a.id === e.by);
  if (!from) return; // out of sight
  const to = e.hit && all.find((a) => a.id === e.hit);
  let x2, y2;
  if (to) { x2 = to.x; y2 = to.y; } else {
    const dx = Math.cos(from.theta), dy = Math.sin(from.theta);
    const reach = rules.tag.range;
    const r = segs ? castRay(segs, from.x, from.y, dx, dy, reach) : reach;
    x2 = from.x + dx * r; y2 = from.y + dy * r;
  }
  const color = e.by.startsWith("r") ? "#9fdcff" : "#ff6b8b";
  beams.push({ x1: from.x, y1: from.y, x2, y2, t0: performance.now(), color });
  if (beams.length > MAX_BEAMS) beams.shift();
}

/** Agents of `b`, moved `f` of the way from where they were in `a` (f > 1 extrapolates). */
export function between(a, b, f) {
  const move = (list0, list1) => list1.map((q) => {
    const p = list0.find((x) => x.id === q.id);
    // Anonymous sightings (`o?`) cannot be told apart: each is shown where it was seen.
    if (!p || q.tagged || q.id === "o?") return q;
    return { ...q, x: p.x + (q.x - p.x) * f, y: p.y + (q.y - p.y) * f, theta: p.theta + angleDiff(p.theta, q.theta) * f };
  });
  return { robots: move(a.robots, b.robots), opponents: move(a.opponents, b.opponents) };
}

/** The address of replay `id` at `seconds` into it, from `pov` (an opponent's id for what
 * that player saw, "full" for everything) with the robots' belief on or off; `as` keeps the
 * player a full view may switch back to. Opening it lands there, paused (see replay.js). */
export function replayLink(id, { seconds, pov, belief, as }) {
  const q = new URLSearchParams({ t: String(+seconds.toFixed(2)), pov: pov || "full", belief: belief ? "1" : "0" });
  if (as && (pov || "full") === "full") q.set("as", as);
  return `${location.origin}${location.pathname}#/replay/${encodeURIComponent(id)}?${q}`;
}

/** Copies `url` for the person to paste (and keeps it where tests read it); where the page
 * may not write the clipboard, the button's status line shows the address instead. */
export async function copyLink(url, status) {
  const debug = (window.__lasertag = window.__lasertag || {});
  debug.sharedLink = url;
  try {
    await navigator.clipboard.writeText(url);
    status.textContent = "link copied";
  } catch {
    status.textContent = url;
  }
}
