// The rules every match plays by, as the server states them (`GET /api/rules`, docs/api.md):
// the laser's reach and field of view, the tag's range, the agents' radius. Fetched once, when
// the page loads, before anything that draws a match runs (a module's top-level await).

async function load() {
  const r = await fetch("/api/rules");
  if (!r.ok) throw new Error(`GET /api/rules: ${r.status}`);
  return r.json();
}

export const rules = await load();

/** The laser's field of view in radians. */
export const laserFov = (rules.laser.fov_deg * Math.PI) / 180;
