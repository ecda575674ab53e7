// The names this browser keeps (`POST /api/names`, docs/api.md "Names people keep"): their
// tokens in `localStorage["lasertag.names"]`, a claim made for a seat and given up again
// when the seat is refused, and why a name plays unkept (and so unrated) when it could not
// be kept.

const debug = (window.__lasertag = window.__lasertag || {});
/** Why each name this tab plays could not be kept, by name (the HUD says it). */
const UNKEPT = "lasertag.unkept";

/** The tokens of the names this browser keeps, by name. */
export function keptNames() {
  try {
    return JSON.parse(localStorage.getItem("lasertag.names") || "{}") || {};
  } catch {
    return {};
  }
}

function unkeptNames() {
  try {
    return JSON.parse(sessionStorage.getItem(UNKEPT) || "{}") || {};
  } catch {
    return {};
  }
}

/** Why `name` plays unkept in this tab (no rating), or null when it is kept here or was
 * never refused. */
export function unkeptReason(name) {
  if (keptNames()[name]) return null;
  return unkeptNames()[name] || null;
}

function noteUnkept(name, why) {
  const all = unkeptNames();
  all[name] = why;
  sessionStorage.setItem(UNKEPT, JSON.stringify(all));
  debug.nameUnkept = { name, why };
}

/** `name`'s claim on the node at `base`: `{token, fresh}`, the token kept in this browser
 * or claimed now (a name is claimed the first time it plays here, so its rating is its
 * own), `fresh` when it was claimed by this call. `token` is null when the server keeps no
 * names or this address keeps its most: the name then plays unkept, unrated
 * (`unkeptReason`). A name somebody else keeps, or no name at all, is an error naming it. */
export async function claimName(name, base) {
  const kept = keptNames();
  if (kept[name]) return { token: kept[name], fresh: false };
  const r = await fetch(`${base}/api/names`, {
    method: "POST",
    headers: { "content-type": "application/json" },
    body: JSON.stringify({ name }),
  });
  const data = await r.json().catch(() => null);
  if (r.status === 201 && data) {
    kept[name] = data.name_token;
    kept[data.name] = data.name_token;
    localStorage.setItem("lasertag.names", JSON.stringify(kept));
    debug.nameKept = data.name;
    return { token: data.name_token, fresh: true, as: data.name };
  }
  if (r.status === 409 || r.status === 400) {
    throw new Error(data && data.error ? `${data.error}; change “Your name” above` : `${r.status}`);
  }
  noteUnkept(name, r.status === 429
    ? "this address already keeps as many names as the server allows"
    : "this server keeps no names now");
  return { token: null, fresh: false };
}

/** The token of `name`'s claim (see `claimName`), or null when it plays unkept. */
export async function nameToken(name, base) {
  return (await claimName(name, base)).token;
}

/** Gives up a claim `claimName` made for a seat that was then refused: the browser that
 * never played keeps nothing, and the name is free again. */
export async function releaseName(name, claim, base) {
  if (!claim || !claim.fresh) return;
  const kept = keptNames();
  const as = claim.as || name;
  const r = await fetch(`${base}/api/names/${encodeURIComponent(as)}`, {
    method: "DELETE",
    headers: { authorization: `Bearer ${claim.token}` },
  }).catch(() => null);
  // Kept on a failure to reach the server: the token is still the name's.
  if (!r || !(r.ok || r.status === 404)) return;
  for (const n of [name, as]) if (kept[n] === claim.token) delete kept[n];
  localStorage.setItem("lasertag.names", JSON.stringify(kept));
  debug.nameReleased = as;
}
