// The rules every match plays by, as the server states them (`GET /api/rules`, docs/api.md):
// the laser's reach and field of view, the tag's range, the agents' radius. Fetched once, when
// the page loads, before anything that draws a match runs (a module's top-level await).

// A busy server (429, 503) or a dropped connection is asked again a few times, backing off;
// if it never answers, the page says so instead of staying blank (nothing can be drawn
// without the rules).
async function load() {
  let why = "";
  for (const wait of [0, 500, 1000, 2000, 4000]) {
    if (wait) await new Promise((done) => setTimeout(done, wait));
    try {
      const r = await fetch("/api/rules");
      if (r.ok) return await r.json();
      why = `the server answered ${r.status}`;
    } catch (e) {
      why = `the server could not be reached (${e.message})`;
    }
  }
  const note = document.createElement("p");
  note.setAttribute("role", "alert");
  note.textContent = `This page needs the game's rules (GET /api/rules), and ${why}. Reload to try again.`;
  document.body.prepend(note);
  throw new Error(`GET /api/rules: ${why}`);
}

export const rules = await load();

/** The laser's field of view in radians. */
export const laserFov = (rules.laser.fov_deg * Math.PI) / 180;
