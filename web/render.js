// Drawing the arena on a canvas. Pure drawing: `draw` gets a scene (already interpolated)
// and returns counts of what it drew, which the page exposes for tests (window.__lasertag).

import { fan } from "./geometry.js";
import { rules, laserFov } from "./rules.js";

export const COLORS = {
  floor: "#161c25",
  grid: "#1e2632",
  wall: "#3a4556",
  wallEdge: "#7d8ba1",
  robot: "#58a6ff",
  robotFrozen: "#9fb3c8",
  opponent: "#ff4d6d",
  you: "#ffd166",
  fan: "rgba(88, 166, 255, 0.11)",
  fanEdge: "rgba(88, 166, 255, 0.35)",
  goal: "rgba(120, 200, 255, 0.8)",
  cloud: "rgba(170, 255, 120, 0.85)",
  estimate: "rgba(170, 255, 120, 0.9)",
  shade: "rgba(3, 5, 9, 0.62)",
  lit: "rgba(255, 225, 160, 0.05)",
};

// Particle opacity by the role's confidence state (world-model confidence).
const STATE_ALPHA = { valid: 0.75, suspicious: 0.55, invalid: 0.4 };

// One colour per belief role, picked by role id: bright, distinct on the dark floor and
// from the agents' own colours.
export const ROLE_PALETTE = [
  "#ffb000", "#00e0ff", "#ff5fd2", "#7dff6b", "#b48cff", "#ff8a3d", "#3de0c0", "#fff06a",
];

export function roleColor(id) {
  return ROLE_PALETTE[((id % ROLE_PALETTE.length) + ROLE_PALETTE.length) % ROLE_PALETTE.length];
}

/** World-to-screen transform fitting the map in the canvas (y up in the world). A map whose
 * long side lies across a tall screen (a phone held upright) is turned a quarter turn when
 * that shows it markedly larger (`rot`): `x`/`y` then place points in the turned frame,
 * which `draw` turns back with the canvas's own transform; text stays upright. Room is kept
 * for the HUD's lines unless `hud` is false (a thumbnail has none). */
export function fit(canvas, map, { hud: withHud = true } = {}) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr);
    canvas.height = Math.round(h * dpr);
  }
  // Room for the HUD's line above and the controls below (a small canvas keeps less).
  const margin = Math.min(28, 0.04 * Math.min(w, h));
  const hud = withHud ? Math.min(40, 0.08 * Math.max(w, h)) : 0;
  const upright = Math.min((w - 2 * margin) / map.width, (h - 2 * margin - hud) / map.height);
  // Turned, the screen's height (with the HUD's room) runs along the map's width.
  const turned = Math.min((h - 2 * margin - hud) / map.width, (w - 2 * margin) / map.height);
  const rot = turned > upright * 1.15;
  const [fw, fh] = rot ? [h, w] : [w, h];
  const s = rot ? turned : upright;
  const ox = (fw - map.width * s) / 2 + (rot ? hud / 3 : 0);
  const oy = (fh - map.height * s) / 2 + (rot ? 0 : hud / 3);
  return {
    dpr, s, ox, oy, rot, width: w,
    x: (x) => ox + x * s,
    y: (y) => oy + (map.height - y) * s,
  };
}

/** Sets the canvas's transform for frame `v`: device pixels, and the quarter turn if any
 * (the turned frame's x runs down the screen, its y from right to left). */
function frame(ctx, v) {
  if (v.rot) ctx.setTransform(0, v.dpr, -v.dpr, 0, v.width * v.dpr, 0);
  else ctx.setTransform(v.dpr, 0, 0, v.dpr, 0, 0);
}

/** Runs `text()` with the origin at (px, py) of frame `v` and the text upright on screen. */
function upright(ctx, v, px, py, text) {
  ctx.save();
  ctx.translate(px, py);
  if (v.rot) ctx.rotate(-Math.PI / 2);
  text();
  ctx.restore();
}

function path(ctx, v, pts) {
  ctx.beginPath();
  pts.forEach((p, i) => (i ? ctx.lineTo(v.x(p[0]), v.y(p[1])) : ctx.moveTo(v.x(p[0]), v.y(p[1]))));
  ctx.closePath();
}

function disc(ctx, v, x, y, r, fill, stroke, width = 2) {
  ctx.beginPath();
  ctx.arc(v.x(x), v.y(y), r * v.s, 0, Math.PI * 2);
  ctx.fillStyle = fill;
  ctx.fill();
  if (stroke) {
    ctx.lineWidth = width;
    ctx.strokeStyle = stroke;
    ctx.stroke();
  }
}

function heading(ctx, v, x, y, theta, len, color) {
  ctx.beginPath();
  ctx.moveTo(v.x(x), v.y(y));
  ctx.lineTo(v.x(x + Math.cos(theta) * len), v.y(y + Math.sin(theta) * len));
  ctx.lineWidth = 3;
  ctx.strokeStyle = color;
  ctx.stroke();
}

function label(ctx, v, x, y, text, color, above = 0.42) {
  ctx.font = "600 12px system-ui, sans-serif";
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.lineWidth = 3;
  ctx.strokeStyle = "rgba(0,0,0,0.75)";
  ctx.fillStyle = color;
  // Above the agent on screen, whichever way the map is turned.
  const up = above * v.s;
  const [px, py] = v.rot ? [v.x(x) - up, v.y(y)] : [v.x(x), v.y(y) - up];
  upright(ctx, v, px, py, () => {
    ctx.strokeText(text, 0, 0);
    ctx.fillText(text, 0, 0);
  });
}

/**
 * Draws one frame. `scene`: { map, segs, view: "player" | "spectator", you, robots,
 * opponents, belief (or null), visible (polygon or null), beams, now }.
 */
export function draw(ctx, v, scene) {
  const { map } = scene;
  const counts = {
    walls: 0, robots: 0, opponents: 0, particles: 0, roles: 0, fans: 0, beams: 0, localisation: 0,
  };
  ctx.setTransform(1, 0, 0, 1, 0, 0);
  ctx.fillStyle = "#0d1117";
  ctx.fillRect(0, 0, ctx.canvas.width, ctx.canvas.height);
  frame(ctx, v);

  // Floor with a one-metre grid.
  ctx.fillStyle = COLORS.floor;
  ctx.fillRect(v.x(0), v.y(map.height), map.width * v.s, map.height * v.s);
  ctx.strokeStyle = COLORS.grid;
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (let x = 1; x < map.width; x++) { ctx.moveTo(v.x(x), v.y(0)); ctx.lineTo(v.x(x), v.y(map.height)); }
  for (let y = 1; y < map.height; y++) { ctx.moveTo(v.x(0), v.y(y)); ctx.lineTo(v.x(map.width), v.y(y)); }
  ctx.stroke();

  // The player's view: light what it sees.
  if (scene.visible) {
    ctx.fillStyle = COLORS.lit;
    path(ctx, v, scene.visible);
    ctx.fill();
  }

  // Laser fans (spectators: the real scan; players: the fan clipped by walls).
  for (const r of scene.robots) {
    if (r.frozen) continue;
    let pts;
    if (r.scan && r.scan.length) {
      const n = r.scan.length;
      pts = r.scan.map((cm, i) => {
        const a = r.theta + ((i - (n - 1) / 2) * laserFov) / (n - 1);
        const d = cm / 100;
        return [r.x + Math.cos(a) * d, r.y + Math.sin(a) * d];
      });
    } else {
      // Fewer beams than the laser's: the drawn fan only needs its outline.
      pts = fan(scene.segs, r.x, r.y, r.theta, 61, rules.laser.range, laserFov);
    }
    path(ctx, v, [[r.x, r.y], ...pts]);
    ctx.fillStyle = COLORS.fan;
    ctx.fill();
    ctx.lineWidth = 1;
    ctx.strokeStyle = COLORS.fanEdge;
    ctx.stroke();
    counts.fans++;
  }

  // Belief: each role's particles in its own colour, its count at the cloud's mean.
  if (scene.belief) {
    for (const role of scene.belief.roles) {
      const color = roleColor(role.id);
      const p = role.points;
      if (role.tagged) {
        const x = v.x(p[0] / 100), y = v.y(p[1] / 100);
        ctx.strokeStyle = "rgba(200,200,200,0.6)";
        ctx.lineWidth = 2;
        ctx.beginPath();
        ctx.moveTo(x - 5, y - 5); ctx.lineTo(x + 5, y + 5);
        ctx.moveTo(x + 5, y - 5); ctx.lineTo(x - 5, y + 5);
        ctx.stroke();
        continue;
      }
      counts.roles++;
      ctx.fillStyle = color;
      // Trust shows as strength: a confirmed cloud is vivid, a guess is faint.
      ctx.globalAlpha = STATE_ALPHA[role.state] ?? 0.6;
      const size = Math.max(2.5, v.s * 0.07);
      for (let i = 0; i + 1 < p.length; i += 2) {
        ctx.fillRect(v.x(p[i] / 100) - size / 2, v.y(p[i + 1] / 100) - size / 2, size, size);
        counts.particles++;
      }
      ctx.globalAlpha = 1;
    }
    // Labels on top of every cloud.
    for (const role of scene.belief.roles) {
      if (role.tagged) continue;
      const color = roleColor(role.id);
      const [mx, my] = role.mean;
      ctx.beginPath();
      ctx.arc(v.x(mx), v.y(my), 9, 0, Math.PI * 2);
      ctx.lineWidth = 2;
      ctx.strokeStyle = color;
      ctx.fillStyle = "rgba(13,17,23,0.8)";
      ctx.fill();
      // Solid ring: valid; dashed: suspicious (a robot will go and check); dotted: a guess.
      ctx.setLineDash(role.state === "suspicious" ? [4, 3] : role.state === "invalid" ? [1, 3] : []);
      ctx.stroke();
      ctx.setLineDash([]);
      ctx.font = "700 11px system-ui, sans-serif";
      ctx.textAlign = "center";
      ctx.textBaseline = "middle";
      ctx.fillStyle = color;
      upright(ctx, v, v.x(mx), v.y(my), () => ctx.fillText(String(role.count), 0, 0.5));
    }
  }

  // Walls.
  for (const poly of map.obstacles) {
    path(ctx, v, poly);
    ctx.fillStyle = COLORS.wall;
    ctx.fill();
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = COLORS.wallEdge;
    ctx.stroke();
    counts.walls++;
  }
  ctx.lineWidth = 3;
  ctx.strokeStyle = COLORS.wallEdge;
  ctx.strokeRect(v.x(0), v.y(map.height), map.width * v.s, map.height * v.s);

  // Shade what the player cannot see.
  if (scene.visible) {
    ctx.beginPath();
    ctx.rect(v.x(0), v.y(map.height), map.width * v.s, map.height * v.s);
    scene.visible.forEach((p, i) => (i ? ctx.lineTo(v.x(p[0]), v.y(p[1])) : ctx.moveTo(v.x(p[0]), v.y(p[1]))));
    ctx.closePath();
    ctx.fillStyle = COLORS.shade;
    ctx.fill("evenodd");
  }

  // Robots' goals (spectators).
  for (const r of scene.robots) {
    if (!r.goal) continue;
    ctx.setLineDash([4, 5]);
    ctx.beginPath();
    ctx.moveTo(v.x(r.x), v.y(r.y));
    ctx.lineTo(v.x(r.goal.x), v.y(r.goal.y));
    ctx.lineWidth = 1.5;
    ctx.strokeStyle = COLORS.goal;
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.beginPath();
    ctx.arc(v.x(r.goal.x), v.y(r.goal.y), 5, 0, Math.PI * 2);
    ctx.stroke();
  }

  // Tag beams: a flash along the shooter's heading that fades.
  for (const b of scene.beams) {
    const age = (scene.now - b.t0) / 450;
    if (age >= 1) continue;
    ctx.globalAlpha = 1 - age;
    ctx.beginPath();
    ctx.moveTo(v.x(b.x1), v.y(b.y1));
    ctx.lineTo(v.x(b.x2), v.y(b.y2));
    ctx.lineWidth = 4;
    ctx.strokeStyle = b.color;
    ctx.shadowColor = b.color;
    ctx.shadowBlur = 12;
    ctx.stroke();
    ctx.shadowBlur = 0;
    ctx.globalAlpha = 1;
    counts.beams++;
  }

  // Where each robot believes it is (spectators, with the belief switched on): its
  // localisation particles and a ring at its estimate, so one sees a robot unsure or lost.
  // The ring is as wide as the belief's spread (at least the robot's size): a robot without
  // a localiser has no particles, only its dead-reckoning spread, which keeps growing.
  for (const r of scene.belief ? scene.robots : []) {
    ctx.fillStyle = COLORS.cloud;
    const size = Math.max(1.5, v.s * 0.04);
    const cloud = r.cloud || [];
    for (let i = 0; i + 1 < cloud.length; i += 2) {
      ctx.fillRect(v.x(cloud[i] / 100) - size / 2, v.y(cloud[i + 1] / 100) - size / 2, size, size);
      counts.localisation++;
    }
    if (r.estimate) {
      const radius = Math.max(0.3, Math.min(r.spread || 0, 50));
      ctx.beginPath();
      ctx.arc(v.x(r.estimate.x), v.y(r.estimate.y), radius * v.s, 0, Math.PI * 2);
      ctx.setLineDash([2, 3]);
      ctx.lineWidth = 1.5;
      ctx.strokeStyle = COLORS.estimate;
      ctx.stroke();
      ctx.setLineDash([]);
      heading(ctx, v, r.estimate.x, r.estimate.y, r.estimate.theta, 0.35, COLORS.estimate);
    }
  }

  // Agents.
  for (const r of scene.robots) {
    // A person on the robot team: their own robot in the player's colour.
    const mine = r.id === scene.you;
    const color = r.frozen ? COLORS.robotFrozen : COLORS.robot;
    disc(ctx, v, r.x, r.y, rules.agent_radius, color, mine ? COLORS.you : "#e6f1ff", mine ? 3 : 2);
    heading(ctx, v, r.x, r.y, r.theta, 0.45, mine ? COLORS.you : "#e6f1ff");
    if (r.frozen) {
      ctx.beginPath();
      ctx.arc(v.x(r.x), v.y(r.y), 0.4 * v.s, 0, Math.PI * 2);
      ctx.setLineDash([3, 3]);
      ctx.lineWidth = 2;
      ctx.strokeStyle = "#cfe8ff";
      ctx.stroke();
      ctx.setLineDash([]);
    }
    const who = mine ? "you" : r.name ? `${r.name} (${r.id})` : r.id;
    label(ctx, v, r.x, r.y, r.frozen ? `${who} ❄` : who, mine ? COLORS.you : "#cfe3ff");
    counts.robots++;
  }
  for (const o of scene.opponents) {
    if (o.tagged) continue;
    const mine = o.id === scene.you;
    disc(ctx, v, o.x, o.y, rules.agent_radius, mine ? COLORS.you : COLORS.opponent, "#fff", mine ? 3 : 2);
    if (Number.isFinite(o.theta)) heading(ctx, v, o.x, o.y, o.theta, 0.45, "#fff");
    label(ctx, v, o.x, o.y, mine ? "you" : o.name || o.id, mine ? COLORS.you : "#ffc2cd");
    counts.opponents++;
  }
  return counts;
}
