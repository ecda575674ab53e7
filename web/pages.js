// The pages around the game: past matches (#/history), the leaderboard (#/leaderboard) and
// one name's figures (#/player/<name>). Plain DOM from the JSON of /api/replays,
// /api/leaderboard and /api/players/<name> (docs/api.md).

const $ = (id) => document.getElementById(id);
const debug = (window.__lasertag = window.__lasertag || {});

/** Matches shown per page of the history (and asked of the leaderboard). */
const PAGE = 20;
const TICK_HZ = 20;

/** A request's JSON, or an Error carrying the status and the server's message. */
async function getJson(path) {
  const r = await fetch(path);
  const text = await r.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch { /* not JSON: say the status */ }
  if (!r.ok) {
    const e = new Error(data && data.error ? data.error : `${r.status}`);
    e.status = r.status;
    throw e;
  }
  return data;
}

function fmtTime(s) {
  s = Math.max(0, Math.floor(s));
  return `${Math.floor(s / 60)}:${String(s % 60).padStart(2, "0")}`;
}

/** "3 min ago", or the date for anything older than a day. */
function ago(unix) {
  const s = Date.now() / 1000 - unix;
  if (s < 60) return "just now";
  if (s < 3600) return `${Math.floor(s / 60)} min ago`;
  if (s < 86400) return `${Math.floor(s / 3600)} h ago`;
  return new Date(unix * 1000).toLocaleDateString();
}

const REASONS = {
  all_tagged: "every opponent tagged",
  time_limit: "held out to the time limit",
  stopped: "stopped",
  server_shutdown: "server shut down",
  abandoned: "abandoned",
  overloaded: "server overloaded",
};

function cell(content, cls) {
  const td = document.createElement("td");
  if (content instanceof Node) td.append(content); else td.textContent = content;
  if (cls) td.className = cls;
  return td;
}

function nameLink(name) {
  const a = document.createElement("a");
  a.href = `#/player/${encodeURIComponent(name)}`;
  a.textContent = name;
  return a;
}

/** One finished match as a table row, with a button to watch it again. */
export function replayRow(r) {
  const tr = document.createElement("tr");
  tr.dataset.id = r.id;
  const when = cell(ago(r.ended_at));
  when.title = new Date(r.ended_at * 1000).toLocaleString();
  const players = document.createElement("span");
  if (r.players.length) {
    r.players.forEach((n, i) => players.append(i ? ", " : "", nameLink(n)));
  } else {
    players.textContent = "bots only";
    players.className = "dim";
  }
  const result = document.createElement("span");
  const won = r.winner === "robots" ? "robots won" : r.winner === "opponents" ? "opponents won" : "no winner";
  result.append(Object.assign(document.createElement("strong"), { textContent: won, className: r.winner || "none" }));
  result.append(` · ${REASONS[r.reason] || r.reason || "unknown"}`);
  if (!r.complete) {
    const badge = Object.assign(document.createElement("span"), { className: "badge", textContent: "incomplete" });
    badge.title = "the recording stops before the end: the replay shows what was recorded";
    result.append(" ", badge);
  }
  const watch = document.createElement("button");
  watch.className = "secondary watch";
  watch.textContent = "Watch";
  watch.onclick = () => (location.hash = `#/replay/${encodeURIComponent(r.id)}`);
  const buttons = Object.assign(document.createElement("div"), { className: "buttons" });
  buttons.append(watch);
  tr.append(when, cell(r.map), cell(players), cell(result), cell(fmtTime(r.ticks / TICK_HZ), "num"), cell(buttons));
  return tr;
}

function placeholder(cols, text) {
  const tr = document.createElement("tr");
  const td = cell(text, "dim");
  td.colSpan = cols;
  tr.append(td);
  return tr;
}

// The pages of the history seen before this one, so that "Newer" goes back through them.
const trail = [];

/** #/history, or #/history?before=<id>: the next page of older matches. */
export async function showHistory(before) {
  debug.page = "history";
  debug.historyRows = null;
  const body = $("history-table").tBodies[0];
  $("history-error").textContent = "";
  let rows;
  try {
    const q = new URLSearchParams({ limit: String(PAGE) });
    if (before) q.set("before", before);
    // The showcase runs all day: its runs would crowd out the matches people played.
    const showcase = $("history-showcase");
    showcase.checked = localStorage.getItem("lasertag.history.showcase") === "true";
    showcase.onchange = () => {
      localStorage.setItem("lasertag.history.showcase", String(showcase.checked));
      trail.length = 0;
      if (location.hash === "#/history") showHistory();
      else location.hash = "#/history";
    };
    q.set("showcase", String(showcase.checked));
    rows = await getJson(`/api/replays?${q}`);
  } catch (e) {
    $("history-error").textContent = `cannot list the matches: ${e.message}`;
    body.replaceChildren();
    return;
  }
  body.replaceChildren(...(rows.length ? rows.map(replayRow)
    : [placeholder(6, before ? "no older matches" : "no match has finished yet: play one!")]));
  debug.historyRows = rows.length;
  const older = $("history-older");
  older.disabled = rows.length < PAGE;
  older.onclick = () => {
    trail.push(before || "");
    location.hash = `#/history?before=${encodeURIComponent(rows[rows.length - 1].id)}`;
  };
  const newer = $("history-newer");
  newer.disabled = !before;
  newer.onclick = () => {
    const back = trail.pop();
    location.hash = back ? `#/history?before=${encodeURIComponent(back)}` : "#/history";
  };
}

const BOARDS = [
  ["wins", "Wins"], ["tags", "Tags"], ["survival", "Longest survival"], ["matches", "Matches"],
  ["rating", "Rating"],
];

/** A rating as "1646 ± 368" (two deviations: 95% confidence), or a dash before any rated
 * match (docs/ratings.md). */
function fmtRating(r) {
  return r ? `${Math.round(r.rating)} ± ${Math.round(2 * r.deviation)}` : "—";
}

function statsTable(heads, rows) {
  const table = document.createElement("table");
  const tr = document.createElement("tr");
  for (const h of heads) tr.append(Object.assign(document.createElement("th"), { textContent: h }));
  table.createTHead().append(tr);
  const body = table.createTBody();
  body.append(...rows);
  return table;
}

function noStats(text) {
  return Object.assign(document.createElement("p"), { className: "empty", textContent: text });
}

/** #/leaderboard?by=wins|tags|survival|matches|rating */
export async function showLeaderboard(by) {
  if (!BOARDS.some(([k]) => k === by)) by = "wins";
  debug.page = "leaderboard";
  debug.leaderboard = null;
  $("leaderboard-title").textContent = "Leaderboard";
  $("leaderboard-error").textContent = "";
  $("leaderboard-tabs").replaceChildren(...BOARDS.map(([k, label]) => {
    const b = document.createElement("button");
    b.className = k === by ? "on" : "secondary";
    b.textContent = label;
    b.onclick = () => (location.hash = `#/leaderboard?by=${k}`);
    return b;
  }));
  const out = $("leaderboard-body");
  out.replaceChildren(noStats("loading…"));
  let board;
  try {
    board = await getJson(`/api/leaderboard?by=${by}&limit=${PAGE}`);
  } catch (e) {
    debug.leaderboard = e.status === 404 ? "none" : "error";
    out.replaceChildren(noStats(e.status === 404
      ? "No statistics yet: they appear once people have played matches to the end."
      : `cannot load the leaderboard: ${e.message}`));
    return;
  }
  const players = board.players || [];
  debug.leaderboard = players.length;
  if (!players.length) {
    out.replaceChildren(noStats(by === "rating"
      ? "Nobody is rated yet: play a match with a difficulty preset to the end."
      : "No statistics yet: nobody has finished a match."));
    return;
  }
  const rows = players.map((p, i) => {
    const tr = document.createElement("tr");
    tr.append(cell(String(i + 1), "num"), cell(nameLink(p.name)), cell(String(p.matches), "num"),
      cell(String(p.wins), "num"), cell(String(p.tags), "num"), cell(fmtTime(p.longest_survival_s), "num"),
      cell(fmtRating(p.rating), "num"));
    return tr;
  });
  out.replaceChildren(statsTable(["#", "name", "matches", "wins", "tags", "longest survival", "rating"], rows));
}

/** #/player/<name>: one name's figures and its recent matches. */
export async function showPlayer(name) {
  debug.page = "player";
  debug.player = null;
  $("leaderboard-title").textContent = name;
  $("leaderboard-error").textContent = "";
  const back = document.createElement("button");
  back.className = "secondary";
  back.textContent = "← Leaderboard";
  back.onclick = () => (location.hash = "#/leaderboard");
  $("leaderboard-tabs").replaceChildren(back);
  const out = $("leaderboard-body");
  out.replaceChildren(noStats("loading…"));
  let p;
  try {
    p = await getJson(`/api/players/${encodeURIComponent(name)}`);
  } catch (e) {
    debug.player = e.status === 404 ? "none" : "error";
    out.replaceChildren(noStats(e.status === 404
      ? `Nobody has finished a match as “${name}” yet.`
      : `cannot load ${name}'s figures: ${e.message}`));
    return;
  }
  debug.player = p.name;
  const figures = Object.assign(document.createElement("div"), { className: "figures" });
  for (const [label, value] of [["matches", p.matches], ["wins", p.wins], ["tags", p.tags],
    ["longest survival", fmtTime(p.longest_survival_s)], ["rating", fmtRating(p.rating)]]) {
    const f = document.createElement("div");
    f.append(Object.assign(document.createElement("strong"), { textContent: String(value) }), label);
    figures.append(f);
  }
  const recent = (p.recent || []).map((m) => {
    const tr = replayRow(m);
    if (m.rating_after != null) {
      const change = Math.round(m.rating_after - m.rating_before);
      tr.cells[3].append(` · rating ${change >= 0 ? "+" : ""}${change}`);
    }
    return tr;
  });
  const h = Object.assign(document.createElement("h2"), { textContent: "Recent matches" });
  out.replaceChildren(figures, h, recent.length
    ? statsTable(["ended", "map", "players", "result", "length", ""], recent)
    : noStats("none kept"));
}
