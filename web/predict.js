// Client-side prediction of the player's own opponent, and reconciliation with the server.
//
// The server is the authority, but waiting for it shows every key press a round trip late.
// So the page runs the same motion as the server (core/sim/motion.rs: a disc that turns,
// moves along the tick's mean heading, then slides out of walls and agents) on its own
// numbered inputs, one per 50 ms tick, and draws the result at once. Each snapshot says which
// input the server applied last (`ack`) and where the opponent really is after it: the page
// starts again from there, replays the inputs the server has not applied yet, and hides the
// difference by letting it fade over a few frames (a jump only when it is large).

import { angleDiff } from "./geometry.js";

/** Ticks of correction fade: the drawn disc closes most of a gap within about 100 ms. */
const FADE_MS = 100;
/** A correction larger than this (metres) is shown at once: it was a teleport, not drift. */
const SNAP_M = 1.0;
/** Passes of pushing the disc out of contacts, and the skin it keeps (as the server). */
const PASSES = 4;
const SKIN = 1e-4;

function wrap(a) {
  return Math.atan2(Math.sin(a), Math.cos(a));
}

/** Closest point to (x, y) on segment s = [x1, y1, x2, y2]. */
function closestOn(s, x, y) {
  const ex = s[2] - s[0], ey = s[3] - s[1];
  const len2 = ex * ex + ey * ey;
  let t = len2 > 0 ? ((x - s[0]) * ex + (y - s[1]) * ey) / len2 : 0;
  t = Math.max(0, Math.min(1, t));
  return [s[0] + t * ex, s[1] + t * ey];
}

function insidePolygon(poly, x, y) {
  let inside = false;
  for (let i = 0, j = poly.length - 1; i < poly.length; j = i++) {
    const [xi, yi] = poly[i], [xj, yj] = poly[j];
    if ((yi > y) !== (yj > y) && x < ((xj - xi) * (y - yi)) / (yj - yi) + xi) inside = !inside;
  }
  return inside;
}

export class Predictor {
  /** `map`: the map object; `segs`: its wall segments; `k`: the welcome's `kinematics`. */
  constructor(map, segs, k) {
    this.map = map;
    this.segs = segs;
    this.k = k;
    this.pending = []; // inputs sent and not yet applied by the server: {seq, forward, turn}
    this.pose = null; // predicted pose after every input sent
    this.offset = { x: 0, y: 0, theta: 0 }; // correction still being faded out
    this.others = []; // centres of the other agents in sight, from the latest snapshot
    this.fadeAt = performance.now();
    this.corrections = []; // recent correction sizes (m), for tests and the debug view
  }

  closestWall(x, y) {
    let best = null, bd = Infinity;
    for (const s of this.segs) {
      const q = closestOn(s, x, y);
      const d = Math.hypot(x - q[0], y - q[1]);
      if (d < bd) { bd = d; best = q; }
    }
    return [best, bd];
  }

  insideObstacle(x, y) {
    return this.map.obstacles.some((p) => insidePolygon(p, x, y));
  }

  /** One tick of motion from `pose` with keys `forward`, `turn` (as `motion::propose` and
   * `motion::resolve` on the server). */
  step(pose, forward, turn) {
    const { dt, speed, turn_rate: rate, radius: r } = this.k;
    const theta = wrap(pose.theta + turn * rate * dt);
    const mid = pose.theta + 0.5 * turn * rate * dt;
    const d = forward * speed * dt;
    let x = pose.x + Math.cos(mid) * d, y = pose.y + Math.sin(mid) * d;
    if (d === 0) return { x: pose.x, y: pose.y, theta };
    for (let pass = 0; pass < PASSES; pass++) {
      let moved = false;
      const [q, dist] = this.closestWall(x, y);
      if (q && dist < r) {
        if (dist < 1e-6 || this.insideObstacle(x, y)) return { x: pose.x, y: pose.y, theta };
        x = q[0] + ((x - q[0]) / dist) * (r + SKIN);
        y = q[1] + ((y - q[1]) / dist) * (r + SKIN);
        moved = true;
      }
      for (const o of this.others) {
        const vx = x - o[0], vy = y - o[1];
        const dd = Math.hypot(vx, vy);
        if (dd < 2 * r) {
          if (dd < 1e-6) return { x: pose.x, y: pose.y, theta };
          x = o[0] + (vx / dd) * (2 * r + SKIN);
          y = o[1] + (vy / dd) * (2 * r + SKIN);
          moved = true;
        }
      }
      if (!moved) return { x, y, theta };
    }
    const free = this.closestWall(x, y)[1] >= r && this.others.every((o) => Math.hypot(x - o[0], y - o[1]) >= 2 * r);
    return free ? { x, y, theta } : { x: pose.x, y: pose.y, theta };
  }

  /** An input just sent for the next tick: predicted at once. */
  push(seq, forward, turn) {
    this.pending.push({ seq, forward, turn });
    if (this.pose) this.pose = this.step(this.pose, forward, turn);
  }

  /** A snapshot: `me` is the opponent's true pose after input `ack`; `others` the centres of
   * the other agents it shows. */
  reconcile(me, ack, others) {
    this.others = others;
    this.pending = this.pending.filter((i) => i.seq > ack);
    let p = { x: me.x, y: me.y, theta: me.theta };
    for (const i of this.pending) p = this.step(p, i.forward, i.turn);
    if (this.pose) {
      this.fade(performance.now());
      // Keep the drawn disc where it was; fade the difference out.
      const dx = this.pose.x + this.offset.x - p.x, dy = this.pose.y + this.offset.y - p.y;
      const err = Math.hypot(this.pose.x - p.x, this.pose.y - p.y);
      if (err > 1e-4) this.corrections.push(err);
      if (this.corrections.length > 200) this.corrections.shift();
      if (Math.hypot(dx, dy) > SNAP_M) this.offset = { x: 0, y: 0, theta: 0 };
      else this.offset = { x: dx, y: dy, theta: angleDiff(p.theta, this.pose.theta + this.offset.theta) };
    }
    this.pose = p;
  }

  fade(now) {
    const f = Math.exp(-(now - this.fadeAt) / FADE_MS);
    this.fadeAt = now;
    this.offset = { x: this.offset.x * f, y: this.offset.y * f, theta: this.offset.theta * f };
  }

  /** Where to draw the disc at `now`: the prediction, `frac` of the way through the tick
   * being held with keys `forward`, `turn` (so a key shows in the very next frame), plus
   * what is left of the last correction. */
  drawn(now, frac, forward, turn) {
    if (!this.pose) return null;
    this.fade(now);
    const next = this.step(this.pose, forward, turn);
    const f = Math.max(0, Math.min(1, frac));
    return {
      x: this.pose.x + (next.x - this.pose.x) * f + this.offset.x,
      y: this.pose.y + (next.y - this.pose.y) * f + this.offset.y,
      theta: this.pose.theta + angleDiff(this.pose.theta, next.theta) * f + this.offset.theta,
    };
  }
}
