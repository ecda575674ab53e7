// The page: a lobby (#/), and a match to watch (#/watch/<id>) or play (#/play/<id>); past
// matches (#/history), a replay (#/replay/<id>; `?pov=o0&t=83.5&belief=1`: a player's view, a
// moment, the belief), the leaderboard (#/leaderboard, #/player/<name>), a party's room
// (#/party/<code>) and the queue (#/queue).
// Plain ES modules, no build step, nothing fetched from anywhere but this server and, when it
// runs in a fleet, the other nodes its listing names (a match is played on its own node).

import { Game, debug } from "./game.js";
import { claimName, keptNames, nameToken, releaseName, unkeptReason } from "./names.js";
import { Replay } from "./replay.js";
import { showHistory, showLeaderboard, showPlayer } from "./pages.js";
import { PartyRoom, createParty, normalCode, parties } from "./party.js";
import { QueueView } from "./queue.js";
import { rules } from "./rules.js";
import { Thumbnail } from "./thumbnail.js";

const $ = (id) => document.getElementById(id);
let game = null;
/** The party room or the queue's view, while one shows. */
let together = null;
let lobbyTimer = null;
/** Match id → the URL of the node that hosts it ("" for this page's own server), from the
 * listings (in a fleet every node lists every node's matches, each with its `node`). */
const homes = new Map();

function playerName() {
  const input = $("name");
  let name = input.value.trim();
  if (!name) {
    name = `player-${Math.floor(Math.random() * 900 + 100)}`;
    input.value = name;
  }
  localStorage.setItem("lasertag.name", name);
  return name;
}

/** `path` on the node at `base` ("" for this server): the JSON answer, and the origin that
 * gave it ("" for this server; a new match may be placed on another node, which the
 * browser reaches by following the 307). */
async function request(method, path, body, base = "", bearer = null) {
  const headers = body ? { "content-type": "application/json" } : {};
  if (bearer) headers.authorization = `Bearer ${bearer}`;
  const r = await fetch(base + path, {
    method,
    headers,
    body: body ? JSON.stringify(body) : undefined,
  });
  const text = await r.text();
  const data = text ? JSON.parse(text) : null;
  if (!r.ok) {
    // The server's words, and its status for the page's own (`seatRefused`).
    throw Object.assign(new Error(data && data.error ? data.error : `${r.status}`), { status: r.status });
  }
  const origin = new URL(r.url, location.href).origin;
  return { data, from: origin === location.origin ? "" : origin };
}

async function api(method, path, body, base = "") {
  return (await request(method, path, body, base)).data;
}

/** Lists every match (the fleet's, in a fleet) and remembers where each is hosted. */
async function listMatches() {
  const matches = await api("GET", "/api/matches");
  for (const m of matches) homes.set(m.id, m.node && !m.node.local ? m.node.url : "");
  return matches;
}

/** Creates a match wherever the server places it, and remembers where that is. */
async function createMatch(body) {
  const { data, from } = await request("POST", "/api/matches", body);
  homes.set(data.id, from);
  return data;
}

/** The node that hosts match `id` ("" for this server), looked up in the listing if need be. */
async function homeOf(id) {
  if (!homes.has(id)) {
    try { await listMatches(); } catch { /* then this server: it answers 404 if it must */ }
  }
  return homes.get(id) || "";
}

/** The sessionStorage key of this tab's seat in match `id` on `team`. */
const seatKey = (id, team) => `lasertag.token.${id}${team === "robots" ? ".robots" : ""}`;

/** A refused join in a player's words: why there is no seat, and what to do about it (the
 * server's own message stays in `detail`). */
function seatRefused(e) {
  const said = e.message || "";
  let words = said;
  if (e.status === 429 && /on this server/.test(said)) {
    words = "You already hold as many seats as one address may on this server. A tab you " +
      "closed keeps its seat for a while in case it comes back: go back to that match, or " +
      "try again in a minute.";
  } else if (e.status === 429 && /without playing/.test(said)) {
    words = "You joined this match a moment ago and have not played yet: wait a few " +
      "seconds and try again.";
  } else if (e.status === 429) {
    words = "This address is asking too often: try again in a moment.";
  } else if (e.status === 409 && /one side/.test(said)) {
    words = "You already play on the other side of this match.";
  } else if (e.status === 409 && /free|limit/.test(said)) {
    words = "This match has no free seat left.";
  }
  return Object.assign(new Error(words), { status: e.status, detail: said });
}

/** Takes a seat of match `id` on the node at `base`, on `team` (`opponents`, or `robots` for
 * a pursuer slot), under the lobby's name: the name is claimed first when this browser does
 * not keep it yet, and that claim is given up again when the seat is refused, so a refused
 * join keeps nothing. The seat's token, kept for this tab. */
async function join(id, base, team = "opponents") {
  const name = playerName();
  const claim = await claimName(name, base);
  const body = team === "robots" ? { name, team } : { name };
  if (claim.token) body.name_token = claim.token;
  let joined;
  try {
    joined = await api("POST", `/api/matches/${encodeURIComponent(id)}/players`, body, base);
  } catch (e) {
    await releaseName(name, claim, base);
    throw seatRefused(e);
  }
  sessionStorage.setItem(seatKey(id, team), joined.token);
  return joined.token;
}

/** This tab's seat of match `id` on `team` (taken once per tab), and its token. */
async function tokenFor(id, base, team = "opponents") {
  return sessionStorage.getItem(seatKey(id, team)) || join(id, base, team);
}

/** A match made for this person to play (the doors, the form, Play again): created, then
 * the seat taken before the page goes there. A seat that cannot be taken leaves nothing
 * behind: the match is removed with its owner token and the name's fresh claim given up. */
async function createAndPlay(body, team = "opponents") {
  const m = await createMatch(body);
  const base = homes.get(m.id) || "";
  try {
    await join(m.id, base, team);
  } catch (e) {
    await request("DELETE", `/api/matches/${encodeURIComponent(m.id)}`, null, base, m.owner_token)
      .catch(() => { /* it ends by itself, unplayed, once its hold lapses */ });
    homes.delete(m.id);
    debug.undoneMatch = m.id;
    throw e;
  }
  location.hash = `#/play/${m.id}${team === "robots" ? "?team=robots" : ""}`;
}

/** Takes a seat in whichever showcase has one (the server starts another when all are
 * full) and opens it. */
async function playShowcase() {
  const name = playerName();
  const body = { name };
  const claim = await claimName(name, "");
  if (claim.token) body.name_token = claim.token;
  const seat = await api("POST", "/api/showcase/players", body).catch(async (e) => {
    await releaseName(name, claim, "");
    throw seatRefused(e);
  });
  homes.set(seat.match_id, "");
  sessionStorage.setItem(`lasertag.token.${seat.match_id}`, seat.token);
  location.hash = `#/play/${seat.match_id}`;
}

function fmtTime(s) {
  s = Math.max(0, Math.floor(s));
  return `${Math.floor(s / 60)}:${String(s % 60).padStart(2, "0")}`;
}

function button(text, onclick, cls) {
  const b = document.createElement("button");
  b.textContent = text;
  if (cls) b.className = cls;
  b.onclick = onclick;
  return b;
}

/** The showcase the lobby offers (its listing), and its live thumbnail. */
let showcase = null;
const thumbnail = new Thumbnail($("showcase-view"), (view) => showcase && teaser(showcase, view));

/** The words beside the thumbnail: what its picture shows (`view`, as late as spectators see
 * the match) once it shows something, else the listing's live counts. */
function teaser(show, view) {
  const seat = show.free_slots ? " Play now takes over one of its bots." : "";
  $("showcase-text").textContent = view
    ? `${view.robots} robots hunt ${view.alive} of ${view.opponents} opponents on ${view.map}` +
      (view.delayS ? `, shown ${Math.round(view.delayS)} s behind the players.` : ".") + seat
    : `${show.robots} robots hunt ${show.opponents} opponents on ${show.map}, ` +
      `${fmtTime(show.time_limit_s - show.time_s)} left.${seat}`;
}

/** The lobby's line under the name: the rating of a name this browser keeps. */
async function showOwnRating() {
  const name = $("name").value.trim();
  const out = $("own-rating");
  if (!name || !keptNames()[name]) {
    const unkept = name && unkeptReason(name);
    out.textContent = unkept ? `your name plays unrated here: ${unkept}`
      : name ? "a name is kept, and rated, once it has played here" : "";
    return;
  }
  const r = await fetch(`/api/players/${encodeURIComponent(name)}`).catch(() => null);
  if (name !== $("name").value.trim()) return;
  const p = r && r.ok ? await r.json().catch(() => null) : null;
  const rating = p && p.rating;
  out.textContent = rating
    ? `your rating ${Math.round(rating.rating)} ± ${Math.round(2 * rating.deviation)} over ${rating.matches} rated match${rating.matches === 1 ? "" : "es"}`
    : "your name is kept here; play a rated match for a rating";
  debug.ownRating = rating ? Math.round(rating.rating) : null;
}

async function refreshLobby() {
  let matches;
  try {
    matches = await listMatches();
  } catch (e) {
    $("matches").tBodies[0].innerHTML = `<tr><td colspan="8">cannot reach the server: ${e.message}</td></tr>`;
    return;
  }
  debug.matches = matches.length;
  // Several showcases run while people fill them: offer one with a free slot.
  const shows = matches.filter((m) => m.id.startsWith("showcase-") && m.status === "running");
  // The one the thumbnail already shows stays while it runs; else one with a free slot.
  const show = shows.find((m) => m.id === thumbnail.id) || shows.find((m) => m.free_slots > 0) || shows[0];
  $("showcase").hidden = !show;
  if (show) {
    if (show.id !== thumbnail.id) teaser(show, null);
    thumbnail.show(show.id, homes.get(show.id) || "");
    showcase = show;
    $("showcase-watch").onclick = () => (location.hash = `#/watch/${show.id}`);
    $("showcase-view").onclick = $("showcase-watch").onclick;
    // Join-or-create: the server seats the visitor in a showcase with a free slot, or in
    // one more it starts when every one is full.
    $("showcase-play").onclick = () => playShowcase().catch((e) => ($("lobby-error").textContent = e.message));
  } else {
    thumbnail.stop();
  }
  const rows = matches.map((m) => {
    const tr = document.createElement("tr");
    tr.dataset.id = m.id;
    const left = m.status === "running" ? fmtTime(m.time_limit_s - m.time_s) : `${m.winner} won`;
    const short = m.id.length > 16 ? m.id.slice(0, 16) + "…" : m.id;
    // In a fleet, the node that hosts it (the page plays it there).
    const where = m.node ? ` · ${m.node.id}${m.node.draining ? " (closing)" : ""}` : "";
    // The team: its preset (★ when the match is rated), or its planner; a mixed team names
    // each robot's controller.
    const planner = m.policy ? `policy:${m.policy}` : m.planner;
    const mixed = (m.robot_planners || []).some((p) => p !== (m.policy ? "policy" : m.planner) && p !== "person");
    const team = m.difficulty ? `${m.difficulty}${m.rated ? " ★ rated" : ""}`
      : mixed ? m.robot_planners.join(" + ") : planner;
    const people = m.pursuer_slots ? ` (${m.pursuer_slots} for people)` : "";
    const cells = [short + where, m.map, `${m.robots}${people} · ${team}`,
      `${m.opponents_left}/${m.opponents} ${m.opponent_control}`, m.players, m.spectators, left];
    // Each cell names its column: on a phone the rows are cards, without the header.
    const labels = ["match", "map", "robots", "opponents", "players", "spectators", "time left"];
    cells.forEach((c, i) => {
      const td = document.createElement("td");
      td.textContent = c;
      td.dataset.label = labels[i];
      tr.append(td);
    });
    const td = document.createElement("td");
    const div = document.createElement("div");
    div.className = "buttons";
    div.append(button("Watch", () => (location.hash = `#/watch/${m.id}`), "secondary watch"));
    if (m.free_slots > 0) div.append(button("Play", () => (location.hash = `#/play/${m.id}`), "play"));
    // A free robot of the team: hunt beside the robots.
    if (m.free_pursuer_slots > 0) {
      div.append(button("Hunt", () => (location.hash = `#/play/${m.id}?team=robots`), "play hunt"));
    }
    td.append(div);
    tr.append(td);
    return tr;
  });
  if (!rows.length) rows.push(Object.assign(document.createElement("tr"), { innerHTML: "<td colspan=8>no matches</td>" }));
  // The list is drawn anew every second: a row's button that has the keyboard's focus keeps
  // it (else the focus would go with the old row, back to the top of the page).
  const had = document.activeElement;
  const row = had && had.tagName === "BUTTON" && $("matches").contains(had) ? had.closest("tr").dataset.id : null;
  $("matches").tBodies[0].replaceChildren(...rows);
  if (row) {
    const again = rows.find((tr) => tr.dataset.id === row);
    const same = again && [...again.querySelectorAll("button")].find((b) => b.className === had.className);
    if (same) same.focus();
  }
}

async function loadMaps() {
  const sel = document.querySelector("#create select[name=map]");
  if (sel.options.length) return;
  try {
    for (const m of await api("GET", "/api/maps")) {
      const o = document.createElement("option");
      o.value = m.name;
      o.textContent = `${m.name} (${m.width}×${m.height} m)`;
      sel.append(o);
    }
  } catch { /* the lobby shows the error */ }
}

/** The robot-team presets (GET /api/difficulties): the lobby's first choice, each with
 * how often its robots beat the built-in bots. */
let difficulties = [];

/** Every trained policy the server holds (GET /api/policies) joins the form's planners as a
 * robot team of its own ("policy:<name>"). */
async function loadPolicies() {
  const sel = $("create").elements.planner;
  if (sel.dataset.policies) return;
  let policies;
  try {
    policies = await api("GET", "/api/policies");
  } catch { return; }
  sel.dataset.policies = "1";
  sel.append(...policies.map((p) => {
    const o = document.createElement("option");
    o.value = `policy:${p.name}`;
    o.textContent = `policy:${p.name}${p.shipped ? "" : " (uploaded)"}`;
    return o;
  }));
}

async function loadDifficulties() {
  const sel = $("create").elements.difficulty;
  await loadPolicies();
  if (difficulties.length) return;
  try {
    difficulties = await api("GET", "/api/difficulties");
  } catch { return; /* custom settings still work */ }
  sel.prepend(...difficulties.map((d) => {
    const o = document.createElement("option");
    o.value = d.name;
    o.textContent = d.name;
    return o;
  }));
  sel.value = (difficulties.find((d) => d.default) || difficulties[0]).name;
  sel.onchange = showDifficulty;
  showDifficulty();
  // The Play door offers the same teams, the last one played first.
  const door = $("door-difficulty");
  door.replaceChildren(...difficulties.map((d) => {
    const o = document.createElement("option");
    o.value = d.name;
    o.textContent = d.rating ? `${d.name} (rated ${Math.round(d.rating)})` : d.name;
    return o;
  }));
  const last = localStorage.getItem("lasertag.difficulty");
  door.value = difficulties.some((d) => d.name === last) ? last : sel.value;
}

/** The Play door: a match of one's own against the chosen team, on the map its figures were
 * measured on (what makes it rated), remembered for next time. */
async function playRated() {
  const d = difficulties.find((x) => x.name === $("door-difficulty").value);
  if (!d) throw new Error("the robot teams are still loading; try again in a moment");
  localStorage.setItem("lasertag.difficulty", d.name);
  const map = d.measured.length ? d.measured[0].map : $("create").elements.map.value;
  await createAndPlay({ map, opponents: 1, opponent_control: "human", difficulty: d.name });
}

/** The co-op door: the chosen team plus one robot for the person, against bots that run. */
async function huntWithRobots() {
  const d = difficulties.find((x) => x.name === $("door-difficulty").value);
  // A trained team was trained for its own team size: the person takes one of its robots
  // (the policy drives the others) rather than joining as one more.
  const robots = d && d.policy ? d.robots : Math.min(rules.bounds.robots.maximum, (d ? d.robots : 2) + 1);
  const map = d && d.measured.length ? d.measured[0].map : $("create").elements.map.value;
  await createAndPlay({
    map, opponents: 2, opponent_control: "bot", opponent_bot: "evade", pursuer_slots: 1, robots,
    ...(d ? { difficulty: d.name } : { planner: "coordinated" }),
  }, "robots");
}

/** What each planner does, in a player's words (docs/planner.md, docs/search-planner.md). */
const TEAM_PLANS = {
  coordinated: "tracking you and coordinating",
  search: "tracking you and planning several looks ahead",
  baseline: "searching at random",
  idle: "standing still",
};

/** The chosen preset's settings fill the form (a preset decides them) and its measured
 * figures show beside it; "custom" frees the fields. */
function showDifficulty() {
  const form = $("create");
  const d = difficulties.find((x) => x.name === form.elements.difficulty.value);
  for (const name of ["robots", "planner", "minutes"]) form.elements[name].disabled = Boolean(d);
  debug.difficulty = d ? d.name : "custom";
  if (!d) {
    $("difficulty-note").textContent = "Custom: choose the robots, their planner and the match length yourself.";
    return;
  }
  form.elements.robots.value = d.robots;
  form.elements.planner.value = d.policy ? `policy:${d.policy}` : d.planner;
  // A preset plays for a rating on the map it was measured on: offered first.
  const on = d.measured.length ? d.measured[0].map : null;
  if (on && [...form.elements.map.options].some((o) => o.value === on)) form.elements.map.value = on;
  form.elements.minutes.value = d.time_limit_s / 60;
  const by = Object.fromEntries(d.measured.map((m) => [m.bot, m]));
  const pct = (m) => `${Math.round(100 * m.robots_win_rate)}%`;
  const plan = d.policy
    ? `driven by a trained policy (${d.policy}) from what each robot knows, its team's belief included`
    : TEAM_PLANS[d.planner] || d.planner;
  const team = `${d.robots} robot${d.robots > 1 ? "s" : ""} at ${d.robot_speed} m/s, ` +
    `${plan}, ` +
    `${d.tag_cooldown_s} s between tags, ${d.time_limit_s / 60} minutes`;
  const measured = by.evade && by.wander
    ? ` Measured on ${by.evade.map}: the robots win ${pct(by.evade)} of matches against a bot that runs from them ` +
      `(median tag ${Math.round(by.evade.median_tag_s)} s) and ${pct(by.wander)} against one that wanders ` +
      `(${Math.round(by.wander.median_tag_s)} s).`
    : "";
  const rated = d.rating
    ? ` One person against it on ${on || "its map"} (people, 1 opponent) plays for a rating; this team stands at ${Math.round(d.rating)}.`
    : "";
  $("difficulty-note").textContent = `${d.name[0].toUpperCase()}${d.name.slice(1)}: ${team}.${measured}${rated}`;
}

async function create(e) {
  e.preventDefault();
  const f = new FormData($("create"));
  $("create-error").textContent = "";
  const preset = difficulties.find((d) => d.name === f.get("difficulty"));
  // Co-op and versus: the creator hunts on the team's last robot (a pursuer slot).
  const mode = f.get("mode");
  const hunter = mode === "coop" || mode === "versus";
  try {
    // A preset decides the team and the clock (FormData leaves the disabled fields out).
    const team = preset ? { difficulty: preset.name } : {
      robots: Number(f.get("robots")),
      planner: f.get("planner"),
      time_limit_s: Number(f.get("minutes")) * 60,
    };
    const control = mode === "coop" ? "bots" : mode === "versus" ? "human" : f.get("control");
    // The hunter's robot joins the team: one robot more than the preset or the form says.
    if (hunter) {
      const robots = preset ? preset.robots : Number(f.get("robots"));
      const trained = (preset && preset.policy) || String(f.get("planner")).startsWith("policy:");
      team.robots = trained ? robots : Math.min(rules.bounds.robots.maximum, robots + 1);
    }
    await createAndPlay({
      map: f.get("map"),
      opponents: Number(f.get("opponents")),
      opponent_control: control === "human" ? "human" : "bot",
      bots_joinable: control === "bots" && mode === "hunted",
      ...(hunter ? { pursuer_slots: 1, opponent_bot: "evade" } : {}),
      ...team,
    }, hunter ? "robots" : "opponents");
  } catch (err) {
    $("create-error").textContent = err.message;
  }
}

/** Play again: the next showcase, or a new match like this one. */
async function replay(g) {
  const matches = await listMatches();
  if (g.matchId.startsWith("showcase-")) {
    const next = matches.find((m) => m.id.startsWith("showcase-") && m.status === "running" && m.free_slots > 0);
    location.hash = next ? `#/play/${next.id}` : "#/";
    return;
  }
  const m = matches.find((x) => x.id === g.matchId);
  if (!m) { location.hash = "#/"; return; }
  const again = {
    map: m.map, opponents: m.opponents, opponent_control: m.opponent_control,
    opponent_bot: m.opponent_bot, bots_joinable: m.bots_joinable,
    ...(m.pursuer_slots ? { pursuer_slots: m.pursuer_slots } : {}),
    ...(m.difficulty ? { difficulty: m.difficulty }
      : { robots: m.robots, planner: m.policy ? `policy:${m.policy}` : m.planner, time_limit_s: m.time_limit_s }),
  };
  if (g.role === "player" || m.free_slots > 0) {
    await createAndPlay(again, g.team === "robots" ? "robots" : "opponents");
    return;
  }
  location.hash = `#/watch/${(await createMatch(again)).id}`;
}

/** What the party and queue pages take from the lobby: its name and the name's token. */
/** What the party's room and the queue's view ask of this page: the player's name, a kept
 * name's token, and where a match they were seated in is played. */
const deps = { playerName, nameToken, playsOn: (id, base) => homes.set(id, base) };

async function route() {
  if (game) { game.stop(); game = null; }
  if (together) { together.stop(); together = null; }
  document.title = "lasertag";
  clearInterval(lobbyTimer);
  thumbnail.stop();
  const [hashPath, hashQuery] = location.hash.split("?");
  const params = new URLSearchParams(hashQuery || "");
  const [, page, id] = hashPath.split("/");
  for (const p of ["history", "leaderboard", "party", "queue"]) $(p).hidden = true;
  // The arena page serves both live matches and replays: each shows its own controls.
  const replaying = page === "replay" && Boolean(id);
  $("game").classList.toggle("replaying", replaying);
  $("replay-bar").hidden = !replaying;
  $("controls").hidden = replaying;
  const back = document.querySelector("#game .back");
  back.href = replaying ? "#/history" : "#/";
  back.textContent = replaying ? "← past matches" : "← lobby";
  if (replaying) {
    $("lobby").hidden = true;
    $("game").hidden = false;
    // A shared link: `pov` (an opponent's id, or "full"), `t` (seconds), `belief` (0 or 1).
    const pov = params.get("pov");
    const t = Number.parseFloat(params.get("t"));
    const belief = params.get("belief");
    game = new Replay({
      id: decodeURIComponent(id),
      as: pov && pov !== "full" ? pov : params.get("as"),
      full: pov === "full" || params.get("view") === "full",
      t: Number.isFinite(t) && t >= 0 ? t : null,
      belief: belief === "1" ? true : belief === "0" ? false : null,
      base: homes.get(decodeURIComponent(id)) || "",
    });
    return;
  }
  if (page === "history" || page === "leaderboard" || (page === "player" && id)) {
    $("lobby").hidden = true;
    $("game").hidden = true;
    if (page === "history") {
      $("history").hidden = false;
      showHistory(params.get("before"));
    } else {
      $("leaderboard").hidden = false;
      if (page === "player") showPlayer(decodeURIComponent(id)); else showLeaderboard(params.get("by"));
    }
    return;
  }
  if ((page === "party" && id) || page === "queue") {
    $("lobby").hidden = true;
    $("game").hidden = true;
    $(page).hidden = false;
    together = page === "party" ? new PartyRoom({ code: normalCode(id), deps }) : new QueueView({ deps });
    return;
  }
  if ((page === "watch" || page === "play") && id) {
    $("lobby").hidden = true;
    $("game").hidden = false;
    const base = await homeOf(decodeURIComponent(id));
    let token = null;
    if (page === "play") {
      try {
        token = await tokenFor(decodeURIComponent(id), base, params.get("team") === "robots" ? "robots" : "opponents");
      } catch (e) {
        debug.joinError = e.message;
        location.hash = "#/";
        $("lobby-error").textContent = `cannot join: ${e.message}`;
        return;
      }
    }
    // A party's match: its end card's Again goes back to the room.
    const party = token ? parties.ofMatch(decodeURIComponent(id)) : null;
    game = new Game({
      matchId: decodeURIComponent(id), token, base,
      onAgain: party ? () => (location.hash = `#/party/${party}`) : null,
      onLobby: () => (location.hash = "#/"),
      onReplay: (g) => replay(g).catch((e) => { $("end-text").textContent = e.message; }),
      onStaleToken: token ? () => {
        const team = params.get("team") === "robots" ? ".robots" : "";
        sessionStorage.removeItem(`lasertag.token.${decodeURIComponent(id)}${team}`);
        route();
      } : null,
    });
    return;
  }
  debug.page = "lobby";
  $("game").hidden = true;
  $("lobby").hidden = false;
  // The presets choose their map, so the maps are there first.
  loadMaps().then(loadDifficulties);
  refreshLobby();
  showOwnRating();
  lobbyTimer = setInterval(refreshLobby, 1000);
}

// The page's modules wait for the rules (rules.js) before this runs: on a slow link a name
// typed meanwhile is kept.
if (!$("name").value) $("name").value = localStorage.getItem("lasertag.name") || "";
// The form's ranges and defaults are the server's; the page offers no more opponents than
// index.html's `max` (fewer than a match may have).
for (const name of ["robots", "opponents"]) {
  const bound = rules.bounds[name], input = $("create").elements[name];
  input.min = bound.minimum;
  input.value = bound.default;
  if (!input.max) input.max = bound.maximum;
}
$("create").addEventListener("submit", create);
let ratingTimer = null;
$("name").addEventListener("input", () => {
  clearTimeout(ratingTimer);
  ratingTimer = setTimeout(showOwnRating, 400);
});
const lobbyError = (e) => ($("lobby-error").textContent = e.message);
$("door-play").onclick = () => playRated().catch(lobbyError);
$("door-hunt").onclick = () => huntWithRobots().catch(lobbyError);
$("door-party").onclick = () => createParty(deps).catch(lobbyError);
$("door-queue").onclick = () => (location.hash = "#/queue");
// Co-op and versus decide who the opponents are.
$("create").elements.mode.addEventListener("change", (e) => {
  const mode = e.target.value;
  const control = $("create").elements.control;
  control.disabled = mode !== "hunted";
  if (mode !== "hunted") control.value = mode === "coop" ? "bots" : "human";
  debug.mode = mode;
});
window.addEventListener("hashchange", route);
route();
