"""The PettingZoo ``ParallelEnv``: every robot of a lasertag team is an agent.

Each environment step is one ``POST /api/matches/{id}/act``: every robot's command goes in,
the match advances ``ticks_per_step`` ticks, and every robot's observation and the
ticks' events come back. ``reset`` deletes the episode's match and creates a fresh one
with the episode's seed; a match is a pure function of (map, settings, seed, inputs by
tick), so the same seed and the same actions give the same episode, bit for bit.
"""

from __future__ import annotations

import os
from typing import Any

from .args import DEFAULT_REWARDS, check_arguments
from .client import Client, ServerError, error_message, loads
from .observation import ObservationLayout
from .render import Renderer, check_scale
from .rules import SHIPPED, check_bound, check_detections, check_max_steps, fetch
from .server import LocalServer
from .team import TeamEnv

__all__ = ["LasertagParallelEnv", "parallel_env", "DEFAULT_REWARDS"]

TICK_HZ = SHIPPED["tick_hz"]

class LasertagParallelEnv(TeamEnv):
    """Robots ``r0 … r{n-1}`` of a lasertag match, driven through the HTTP API.

    See :func:`parallel_env` for the arguments, and docs/research.md for the spaces,
    rewards and episode ends.
    """

    def __init__(
        self,
        server: str | LocalServer | None = None,
        map: str | dict = "office",
        robots: int = 2,
        opponents: int = 1,
        seed: int = 0,
        opponent_bot: str = "wander",
        max_steps: int | None = 1200,
        ticks_per_step: int = 1,
        render_mode: str | None = None,
        admin_token: str | None = None,
        time_limit_s: float | None = None,
        placement: str | None = None,
        detections: int | None = None,
        rewards: dict | None = None,
        match_settings: dict | None = None,
        team_tracker: bool = True,
        pixels_per_metre: float = 20.0,
        packed_scans: bool = True,
        planner: str | list = "api",
    ):
        # Types here; ranges once the server has said its bounds (below).
        check_arguments(
            robots=robots, opponents=opponents, ticks_per_step=ticks_per_step, seed=seed,
            max_steps=max_steps, detections=detections, render_mode=render_mode,
            render_modes=self.metadata["render_modes"], rewards=rewards,
            match_settings=match_settings, map=map,
        )

        self.render_mode = render_mode
        self.max_steps = max_steps
        self.ticks_per_step = ticks_per_step
        self.rewards = {**DEFAULT_REWARDS, **(rewards or {})}
        self._owned_server: LocalServer | None = None
        self._client: Client | None = None
        self._closed = False
        self._packed_scans = bool(packed_scans)
        self.match_id: str | None = None
        self.agents: list[str] = []

        # The server: a URL, a shared LocalServer, or one of our own.
        if server is None:
            self._owned_server = LocalServer()
            url, token = self._owned_server.url, self._owned_server.admin_token
        elif isinstance(server, LocalServer):
            url, token = server.url, server.admin_token
        elif isinstance(server, str):
            url = server
            token = admin_token if admin_token is not None else os.environ.get("LASERTAG_ADMIN_TOKEN")
        else:
            raise TypeError("server must be None, a URL such as 'http://127.0.0.1:8080' or a LocalServer")
        try:
            self._client = Client(url, token)
            self._check_server()
            self.rules = fetch(self._client)
            check_bound(self.rules, "robots", robots)
            check_bound(self.rules, "opponents", opponents)
            check_bound(self.rules, "ticks", ticks_per_step, "ticks_per_step")
            check_detections(self.rules, detections)
            check_max_steps(self.rules, max_steps)
            if time_limit_s is not None:
                check_bound(self.rules, "time_limit_s", time_limit_s)
            if isinstance(map, str):
                self.map_def = self._fetch_map(map)
            else:
                self.map_def = map
            check_scale(self.map_def, pixels_per_metre)
        except BaseException:
            self.close()
            raise

        self._create = {
            "map": map,
            "robots": robots,
            "opponents": opponents,
            "opponent_bot": opponent_bot,
            "planner": planner if isinstance(planner, str) else list(planner),
            "clock": "manual",
        }
        if time_limit_s is not None:
            self._create["time_limit_s"] = time_limit_s
        if placement is not None:
            self._create["placement"] = placement
        if not team_tracker:
            # At its minimum a tick costs about a third less (docs/research.md, "Speed"),
            # but the belief parts of the observation are coarser than a served team's.
            self._create["tracker"] = {"particles_per_role": 10}
        self._create.update(match_settings or {})

        try:
            self._init_team(robots, ObservationLayout(
                robots, opponents if detections is None else detections,
                self.map_def["width"], self.map_def["height"], self.rules,
            ), seed, planner)
        except BaseException:
            self.close()
            raise
        self._owner: str | None = None
        self._act_path = ""
        # The end of every act body: ticks, and packed scans when the server offers them
        # (see _check_server).
        self._act_tail = '},"ticks":%d%s}' % (
            ticks_per_step, ',"scans":"hex"' if self._packed_scans else ""
        )
        self.tick = 0
        self.steps = 0
        self.last_events: list[dict] = []
        self._renderer: Renderer | None = None
        self._ppm = pixels_per_metre
        self._raw: dict[str, dict] = {}

    # -- episodes ----------------------------------------------------------------------

    def reset(self, seed: int | None = None, options: dict | None = None):
        """Deletes the episode's match and creates a fresh one.

        ``seed`` seeds the match; without it the first reset uses the constructor's seed and
        later ones draw a seed from a generator seeded by the last seed given, so a
        sequence of unseeded resets is reproducible too. ``options`` is not used.
        """
        self._check_open()
        match_seed = self._match_seed(seed)
        self._delete_match()
        try:
            summary = self._client.call("POST", "/api/matches", {**self._create, "seed": match_seed})
        except ServerError as e:
            if e.status in (400, 404):
                raise ValueError(f"the server refused the match: {e.message}") from None
            raise
        self.match_id = summary["id"]
        # The admin token, when there is one, goes with every request: the owner token
        # would do for changing the match, but only the admin token lifts the per-address
        # request rate (100 a second by default) that would otherwise cap the steps.
        self._owner = self._client.token or summary["owner_token"]
        self._act_path = f"/api/matches/{self.match_id}/act"
        self.episode_seed = match_seed
        self.tick = summary["tick"]
        self._limit_ticks = max(1.0, summary["time_limit_s"] * summary["tick_hz"])
        self.steps = 0
        self.last_events = []
        self.agents = list(self.possible_agents)
        observations, infos = {}, {}
        for i, agent in zip(self._robots, self.possible_agents):
            raw = self._client.call(
                "GET", f"/api/matches/{self.match_id}/robots/{agent}/observation", token=self._owner
            )
            observations[agent] = self.layout.encode(raw, i, 0.0)
            infos[agent] = {"tick": raw["tick"], "observation": raw}
        self._raw = {a: infos[a]["observation"] for a in self.possible_agents}
        return observations, infos

    def step(self, actions: dict[str, Any]):
        """Applies every robot's action (a robot left out stands still), advances the
        match ``ticks_per_step`` ticks and returns PettingZoo's five dictionaries."""
        if not self.agents:
            raise RuntimeError("the episode has ended (or never began): call reset()")
        resp = self._client.raw("POST", self._act_path, self._act_body(actions), self._owner)
        if resp.status != 200:
            message = error_message(resp.body)
            if resp.status == 404:
                raise RuntimeError(
                    f"match {self.match_id} is gone from the server ({message}); call reset()"
                )
            raise ServerError("POST", self._act_path, resp.status, message)
        answer = loads(resp.body)
        tick = answer["tick"]
        ticks = tick - self.tick
        self.tick = tick
        self.steps += 1
        events = answer["events"]
        self.last_events = events

        base = self.rewards["tick"] * ticks
        rewards = dict.fromkeys(self.possible_agents, base)
        tags = dict.fromkeys(self.possible_agents, 0)
        finish = None
        for e in events:
            kind = e["kind"]
            if kind == "tag":
                by = e["by"]
                if by in tags:
                    tags[by] += 1
                    rewards[by] += self.rewards["tag"]
                if self.rewards["team_tag"]:
                    for a in rewards:
                        rewards[a] += self.rewards["team_tag"]
            elif kind == "finished":
                finish = e

        finished = answer["status"] == "finished"
        won = finished and answer["winner"] == "robots"
        out_of_steps = self.max_steps is not None and self.steps >= self.max_steps
        truncate = (finished and not won) or (out_of_steps and not won)
        # How much of the episode is gone, for value estimates near the cut-off: steps of
        # max_steps, or without it the match's time of its limit.
        if self.max_steps is None:
            frac = min(tick / self._limit_ticks, 1.0)
        else:
            frac = min(self.steps / self.max_steps, 1.0)

        raw_obs = answer["observations"]
        raws = [raw_obs[agent] for agent in self.possible_agents]
        vectors = self.layout.encode_all(raws, frac, self._robots)
        observations, infos = {}, {}
        for i, agent in enumerate(self.possible_agents):
            raw = raws[i]
            observations[agent] = vectors[i]
            info = {"tick": tick, "observation": raw, "tags": tags[agent]}
            if finished:
                info["winner"] = answer["winner"]
                info["reason"] = finish["reason"] if finish else None
            infos[agent] = info
        self._raw = dict(zip(self.possible_agents, raws))
        terminations = dict.fromkeys(self.possible_agents, won)
        truncations = dict.fromkeys(self.possible_agents, truncate)
        if won or truncate:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def _act_body(self, actions: dict[str, Any]) -> bytes:
        # Built as text: a few formatted floats are much cheaper than json.dumps over numpy
        # values, and repr(float) round-trips, so the server applies exactly the float32
        # the policy chose (it reads f64 and keeps f32).
        parts = []
        for agent, a in self._team_actions(actions):
            if a is None:
                parts.append(f'"{agent}":{{"forward":0,"turn":0,"tag":false}}')
                continue
            forward, turn, fires = a
            parts.append(
                f'"{agent}":{{"forward":{forward!r},"turn":{turn!r},'
                f'"tag":{"true" if fires else "false"}}}'
            )
        return ('{"commands":{' + ",".join(parts) + self._act_tail).encode()

    def raw_observation(self, agent: str) -> dict:
        """What robot ``agent`` knew after the last reset or step: the server's observation
        object (also ``infos[agent]["observation"]``)."""
        try:
            return self._raw[agent]
        except KeyError:
            raise KeyError(f"no observation of {agent!r}: call reset()") from None

    # -- rendering, state and closing ------------------------------------------------------

    def truth(self) -> dict:
        """The match's ground-truth state (``GET /api/matches/{id}``): every pose, who is
        tagged or frozen. For rendering and analysis; not part of any observation."""
        self._check_open()
        if self.match_id is None:
            raise RuntimeError("no match yet: call reset()")
        return self._client.call("GET", f"/api/matches/{self.match_id}", token=self._owner)

    def render(self):
        """With ``render_mode="rgb_array"``, an (H, W, 3) uint8 frame of the match's truth
        at the current tick (20 pixels per metre by default)."""
        if self.render_mode is None:
            import gymnasium

            gymnasium.logger.warn("render() without a render_mode; pass render_mode='rgb_array'")
            return None
        if self._renderer is None:
            self._renderer = Renderer(self.map_def, self._ppm)
        if self.match_id is None:
            return self._renderer.background.copy()
        return self._renderer.frame(self.truth())

    def close(self) -> None:
        """Deletes the match, closes the connection and stops a server the environment
        started; idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._client is not None:
                self._delete_match()
        except (OSError, ServerError):
            pass  # a server that is already gone has nothing left to delete
        finally:
            if self._client is not None:
                self._client.close()
            if self._owned_server is not None:
                self._owned_server.close()
            self.agents = []

    def __del__(self):  # pragma: no cover - depends on the garbage collector
        try:
            self.close()
        except Exception:
            pass

    # -- helpers -------------------------------------------------------------------------

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("the environment is closed")

    def _delete_match(self) -> None:
        if self.match_id is None:
            return
        mid, self.match_id = self.match_id, None
        try:
            self._client.call("DELETE", f"/api/matches/{mid}", token=self._owner)
        except ServerError as e:
            if e.status != 404:  # removed already (finished and past its grace)
                raise

    def _check_server(self) -> None:
        try:
            doc = self._client.call("GET", "/api/openapi.json")
        except ConnectionRefusedError:
            raise ConnectionRefusedError(f"no lasertag server at {self._client.url}") from None
        if "/api/matches/{id}/act" not in doc.get("paths", {}):
            raise RuntimeError(
                f"the server at {self._client.url} has no POST /api/matches/{{id}}/act: it is "
                "older than this package; rebuild it (cargo build --release)"
            )
        # Packed scans (millimetres in hex) are an opt-in of act that older servers lack;
        # the observations are the same either way (observation.py).
        act = doc.get("components", {}).get("schemas", {}).get("ActRequest", {})
        self._packed_scans = self._packed_scans and "scans" in act.get("properties", {})

    def _fetch_map(self, name: str) -> dict:
        try:
            return self._client.call("GET", f"/api/maps/{name}")
        except ServerError as e:
            if e.status != 404:
                raise
            names = [m["name"] for m in self._client.call("GET", "/api/maps")]
            raise ValueError(f"unknown map {name!r}; the server has {names}") from None


def parallel_env(
    server: str | LocalServer | None = None,
    map: str | dict = "office",
    robots: int = 2,
    opponents: int = 1,
    seed: int = 0,
    opponent_bot: str = "wander",
    max_steps: int | None = 1200,
    ticks_per_step: int = 1,
    render_mode: str | None = None,
    **kwargs,
):
    """A PettingZoo ParallelEnv whose agents are the robots of a lasertag match.

    - ``server``: None (the default) steps the match in-process with the package's native
      engine (:class:`~lasertag_env.native.NativeParallelEnv`); ``"local"`` starts a local
      ``lasertag serve`` (stopped by ``close()``) and drives it over HTTP; a URL uses a
      running server (``admin_token=``, default $LASERTAG_ADMIN_TOKEN, lifts its
      per-address limits); a :class:`LocalServer` is shared and left running. Both
      backends give the same episodes for the same seed and actions.
    - ``map``: a map name (the shipped maps in-process, the server's maps over HTTP), or an
      inline map object (docs/map-format.md).
    - ``robots`` agents ``r0 …``; ``opponents`` bots of kind ``opponent_bot``
      (``wander``, ``evade``, ``idle``); both within the rules' bounds (``GET /api/rules``,
      kept as ``env.rules``).
    - ``seed``: the first episode's match seed (see ``reset``).
    - ``max_steps``: steps before truncation (None: only the match's time limit,
      ``time_limit_s``, 300 s by default); ``ticks_per_step`` ticks (``env.rules["tick_hz"]``
      to a second) per step.
    - ``render_mode``: None or ``"rgb_array"``.
    - keywords: ``time_limit_s``, ``placement`` (``"spawns"`` or ``"random"``),
      ``detections`` (slots in the observation, default ``opponents``), ``rewards``
      (weights, see ``DEFAULT_REWARDS``), ``match_settings`` (further fields of
      ``POST /api/matches``: ``localisation``, ``tracker``, ``radio``, …),
      ``team_tracker`` (default True: the team tracker at its default size, as a match
      people play; False: at its minimum, faster, with coarser belief parts), ``planner`` (``"api"``: every robot is an
      agent; one per robot, e.g. ``["coordinated", "api"]``: a mixed team, whose agents
      are the ``"api"`` robots, ``r1`` here, beside robots the team's planner drives and
      plans around; a team wholly the built-in planner's, ``"coordinated"``, or a trained
      policy's, ``"policy:<name>"``, has no agents: measure it with ``vector_env``),
      ``pixels_per_metre`` (rendering); over
      HTTP also ``admin_token`` and ``packed_scans`` (False: the server writes the scans as
      JSON numbers rather than hex; the observations are the same, bit for bit, and
      slower to get).
    """
    args = dict(
        map=map, robots=robots, opponents=opponents, seed=seed, opponent_bot=opponent_bot,
        max_steps=max_steps, ticks_per_step=ticks_per_step, render_mode=render_mode, **kwargs,
    )
    if server is None:
        from .native import NativeParallelEnv

        for http_only in ("admin_token", "packed_scans"):
            if http_only in kwargs:
                raise TypeError(f"{http_only} is an argument of the HTTP backend (give a server)")
        return NativeParallelEnv(**args)
    return LasertagParallelEnv(server=None if server == "local" else server, **args)
