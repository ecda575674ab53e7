// Map geometry on the client: wall segments and ray casts, for the player's visibility
// region and the robots' laser fans as a player sees them. (What a player is *sent* is
// decided by the server; this only draws the public map.)

/** Every wall edge of a map (obstacle polygons and the border) as [x1, y1, x2, y2]. */
export function segments(map) {
  const segs = [];
  const { width: w, height: h } = map;
  segs.push([0, 0, w, 0], [w, 0, w, h], [w, h, 0, h], [0, h, 0, 0]);
  for (const poly of map.obstacles) {
    for (let i = 0; i < poly.length; i++) {
      const a = poly[i], b = poly[(i + 1) % poly.length];
      segs.push([a[0], a[1], b[0], b[1]]);
    }
  }
  return segs;
}

/** Distance from (x, y) along direction (dx, dy) (unit) to the first wall, at most `max`. */
export function castRay(segs, x, y, dx, dy, max) {
  let best = max;
  for (const s of segs) {
    const ex = s[2] - s[0], ey = s[3] - s[1];
    const den = dx * ey - dy * ex;
    if (Math.abs(den) < 1e-12) continue;
    const fx = s[0] - x, fy = s[1] - y;
    const t = (fx * ey - fy * ex) / den;
    const u = (fx * dy - fy * dx) / den;
    if (t >= 0 && t < best && u >= 0 && u <= 1) best = t;
  }
  return best;
}

/** The region seen from (x, y): a polygon of `n` ray ends (all round, walls occlude). */
export function visibility(segs, x, y, n = 360, max = 60) {
  const pts = new Array(n);
  for (let i = 0; i < n; i++) {
    const a = (i / n) * Math.PI * 2;
    const dx = Math.cos(a), dy = Math.sin(a);
    const r = castRay(segs, x, y, dx, dy, max);
    pts[i] = [x + dx * r, y + dy * r];
  }
  return pts;
}

/** A laser fan: `fov` radians centred on theta at (x, y), `n` beams reaching `range`, each
 * stopped by walls. */
export function fan(segs, x, y, theta, n, range, fov) {
  const pts = [];
  for (let i = 0; i < n; i++) {
    const a = theta + (i / (n - 1) - 0.5) * fov;
    const dx = Math.cos(a), dy = Math.sin(a);
    const r = castRay(segs, x, y, dx, dy, range);
    pts.push([x + dx * r, y + dy * r]);
  }
  return pts;
}

/** Shortest signed difference b - a of two angles. */
export function angleDiff(a, b) {
  let d = (b - a) % (Math.PI * 2);
  if (d > Math.PI) d -= Math.PI * 2;
  if (d < -Math.PI) d += Math.PI * 2;
  return d;
}

/** What a player sees from `me`: an opponent everything in its line of sight; a robot (`laser`:
 * its `{range, fov}`) the fan of its laser, stopped by walls, and nothing while frozen. */
export function sight(segs, me, laser) {
  if (!laser) return visibility(segs, me.x, me.y);
  const reach = me.frozen ? 0.01 : laser.range;
  return [[me.x, me.y], ...fan(segs, me.x, me.y, me.theta, 91, reach, laser.fov)];
}
