"""In-process environments: matches stepped by the package's native engine
(``lasertag_env._native``, the project's Rust core linked into the package), without a
server, HTTP or JSON.

- :class:`NativeParallelEnv`: the PettingZoo ``ParallelEnv`` of :func:`parallel_env` without
  a ``server``. Spaces, rewards, episode ends and seeds are the HTTP backend's, and the same
  seed and actions give the same observations and rewards bit for bit (the tests compare
  whole episodes).
- :class:`LasertagVectorEnv`: many worlds stepped in one call with the GIL released, spread
  over the cores, writing into arrays allocated once (Gymnasium ``VectorEnv`` semantics with
  next-step auto-reset; one entry per robot of each world).

docs/research.md says which to use when.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import _native
from .args import DEFAULT_REWARDS, check_arguments, check_seed
from .observation import ObservationLayout
from .render import Renderer, check_scale
from .rules import SHIPPED, check_bound, check_detections, check_max_steps
from .team import TeamEnv, action_space, agent_robots

__all__ = ["NativeParallelEnv", "LasertagVectorEnv", "vector_env", "shipped_map", "SHIPPED_MAPS"]

TICK_HZ = SHIPPED["tick_hz"]

#: The shipped maps' names (the repository's ``maps/``, built into the engine).
SHIPPED_MAPS = tuple(name for name, _ in _native.shipped_maps())
_MAP_TEXT = dict(_native.shipped_maps())


def shipped_map(name: str) -> dict:
    """The shipped map ``name`` as a map object (docs/map-format.md)."""
    try:
        return json.loads(_MAP_TEXT[name])
    except KeyError:
        raise ValueError(f"unknown map {name!r}; the shipped maps are {list(SHIPPED_MAPS)}") from None


def _check(*, robots, opponents, ticks_per_step, seed, max_steps, detections, render_mode,
           render_modes, rewards, match_settings, map, time_limit_s, rules) -> None:
    """Every argument's type and range that the package can check, before anything is
    allocated for a count (the engine checks them all again, against ``_native.BOUNDS``)."""
    check_arguments(
        robots=robots, opponents=opponents, ticks_per_step=ticks_per_step, seed=seed,
        max_steps=max_steps, detections=detections, render_mode=render_mode,
        render_modes=render_modes, rewards=rewards, match_settings=match_settings, map=map,
    )
    check_bound(rules, "robots", robots)
    check_bound(rules, "opponents", opponents)
    check_bound(rules, "ticks", ticks_per_step, "ticks_per_step")
    check_detections(rules, detections)
    check_max_steps(rules, max_steps)
    if time_limit_s is not None:
        check_bound(rules, "time_limit_s", time_limit_s)


class _Setup:
    """What both in-process environments check and build the same way: the map, the match
    settings, the rules' bounds, the layout and the engine."""

    def __init__(self, *, worlds, map, robots, opponents, seed, opponent_bot, max_steps,
                 ticks_per_step, render_mode, render_modes, time_limit_s, placement,
                 detections, rewards, match_settings, team_tracker, planner="api"):
        self.rules = rules = SHIPPED
        _check(
            robots=robots, opponents=opponents, ticks_per_step=ticks_per_step, seed=seed,
            max_steps=max_steps, detections=detections, render_mode=render_mode,
            render_modes=render_modes, rewards=rewards, match_settings=match_settings, map=map,
            time_limit_s=time_limit_s, rules=rules,
        )
        self.map_def = shipped_map(map) if isinstance(map, str) else map
        self.rewards = {**DEFAULT_REWARDS, **(rewards or {})}
        settings: dict[str, Any] = {
            "robots": robots, "opponents": opponents, "opponent_bot": opponent_bot,
        }
        if planner != "api":
            settings["planner"] = planner if isinstance(planner, str) else list(planner)
        if time_limit_s is not None:
            settings["time_limit_s"] = time_limit_s
        if placement is not None:
            settings["placement"] = placement
        if not team_tracker:
            # As the HTTP backend: the tracker at its minimum (faster; coarser belief parts).
            settings["tracker"] = {"particles_per_role": 10}
        settings.update(match_settings or {})
        k = opponents if detections is None else detections
        laser = rules["laser"]
        self.engine = _native.Engine(
            self.map_def, settings, worlds, int(seed), max_steps, ticks_per_step,
            (float(self.rewards["tag"]), float(self.rewards["team_tag"]),
             float(self.rewards["tick"])),
            k, int(laser["beams"]), float(laser["range"]), float(laser["fov_deg"]),
        )
        self.layout = ObservationLayout(
            robots, k, self.map_def["width"], self.map_def["height"], rules
        )
        if self.engine.size != self.layout.size:  # pragma: no cover - a build out of step
            raise RuntimeError(
                f"the native engine's vector has {self.engine.size} values, the layout "
                f"{self.layout.size}: reinstall the package (pip install ./python)"
            )

    def truth(self, world: int) -> dict:
        tick, robots, opponents = self.engine.truth(world)
        return {
            "tick": tick,
            "robots": [
                {"id": f"r{i}", "x": x, "y": y, "theta": th, "frozen": frozen, "scan": scan}
                for i, (x, y, th, frozen, scan) in enumerate(robots)
            ],
            "opponents": [
                {"id": f"o{i}", "x": x, "y": y, "theta": th, "tagged": tagged}
                for i, (x, y, th, tagged) in enumerate(opponents)
            ],
        }


class NativeParallelEnv(TeamEnv):
    """Robots ``r0 … r{n-1}`` of a lasertag match stepped in-process.

    The arguments are :func:`lasertag_env.parallel_env`'s without ``server``,
    ``admin_token`` and ``packed_scans``. Differences from the HTTP backend: ``infos`` carry
    no raw ``observation`` (ask :meth:`raw_observation`), ``last_events`` stays empty, and
    :meth:`truth` gives poses and scans rather than the server's whole state.
    """

    def __init__(
        self,
        map: str | dict = "office",
        robots: int = 2,
        opponents: int = 1,
        seed: int = 0,
        opponent_bot: str = "wander",
        max_steps: int | None = 1200,
        ticks_per_step: int = 1,
        render_mode: str | None = None,
        time_limit_s: float | None = None,
        placement: str | None = None,
        detections: int | None = None,
        rewards: dict | None = None,
        match_settings: dict | None = None,
        team_tracker: bool = True,
        pixels_per_metre: float = 20.0,
        planner: str | list = "api",
    ):
        # Counts before anything is allocated for them (agent_robots lists the robots), and
        # a bad planner before the engine is built.
        _check(
            robots=robots, opponents=opponents, ticks_per_step=ticks_per_step, seed=seed,
            max_steps=max_steps, detections=detections, render_mode=render_mode,
            render_modes=self.metadata["render_modes"], rewards=rewards,
            match_settings=match_settings, map=map, time_limit_s=time_limit_s, rules=SHIPPED,
        )
        agent_robots(robots, planner)
        self._setup = _Setup(
            worlds=1, map=map, robots=robots, opponents=opponents, seed=seed,
            opponent_bot=opponent_bot, max_steps=max_steps, ticks_per_step=ticks_per_step,
            render_mode=render_mode, render_modes=self.metadata["render_modes"],
            time_limit_s=time_limit_s, placement=placement, detections=detections,
            rewards=rewards, match_settings=match_settings, team_tracker=team_tracker,
            planner=planner,
        )
        self._engine = self._setup.engine
        self.rules = self._setup.rules
        self.map_def = self._setup.map_def
        check_scale(self.map_def, pixels_per_metre)
        self.rewards = self._setup.rewards
        self._init_team(robots, self._setup.layout, seed, planner)
        self.render_mode = render_mode
        self.max_steps = max_steps
        self.ticks_per_step = ticks_per_step
        self.agents: list[str] = []
        # The engine's arrays, allocated once: it writes observations and rewards here.
        self._obs = np.zeros((robots, self.layout.size), dtype=np.float32)
        self._act = np.zeros((robots, 3), dtype=np.float32)
        self._rew = np.zeros(robots, dtype=np.float64)
        self.tick = 0
        self.steps = 0
        self.last_events: list[dict] = []
        self._started = False
        self._closed = False
        self._renderer: Renderer | None = None
        self._ppm = pixels_per_metre

    def reset(self, seed: int | None = None, options: dict | None = None):
        """A fresh match; seeds as the HTTP backend's ``reset`` (the same sequence)."""
        self._check_open()
        match_seed = self._match_seed(seed)
        self._engine.reset(0, match_seed, self._obs)
        self._started = True
        self.episode_seed = match_seed
        self.tick = 0
        self.steps = 0
        self.agents = list(self.possible_agents)
        obs = self._obs.copy()
        observations = {a: obs[i] for i, a in zip(self._robots, self.possible_agents)}
        infos = {a: {"tick": 0} for a in self.possible_agents}
        return observations, infos

    def step(self, actions: dict[str, Any]):
        """Applies every robot's action (a robot left out stands still), advances the match
        ``ticks_per_step`` ticks and returns PettingZoo's five dictionaries."""
        if not self.agents:
            raise RuntimeError("the episode has ended (or never began): call reset()")
        act = self._act
        # (The rows of robots the team plans stay 0: the engine gives them no orders.)
        for i, (_, a) in zip(self._robots, self._team_actions(actions)):
            if a is None:
                act[i] = 0.0
            else:
                forward, turn, fires = a
                act[i] = (forward, turn, 1.0 if fires else 0.0)
        tick, won, truncate, winner, reason, tags = self._engine.step(
            0, act, self._obs, self._rew
        )
        self.tick = tick
        self.steps += 1
        obs = self._obs.copy()
        rew = self._rew.tolist()
        rewards = {a: rew[i] for i, a in zip(self._robots, self.possible_agents)}
        observations, infos = {}, {}
        for i, agent in zip(self._robots, self.possible_agents):
            observations[agent] = obs[i]
            info = {"tick": tick, "tags": tags[i]}
            if winner is not None or reason is not None:
                info["winner"] = winner
                info["reason"] = reason
            infos[agent] = info
        terminations = dict.fromkeys(self.possible_agents, won)
        truncations = dict.fromkeys(self.possible_agents, truncate)
        if won or truncate:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def raw_observation(self, agent: str) -> dict:
        """What robot ``agent`` knows now, as the HTTP API's observation object."""
        self._check_started()
        try:
            robot = self._robots[self.possible_agents.index(agent)]
        except ValueError:
            raise KeyError(f"no agent {agent!r}; the agents are {self.possible_agents}") from None
        return self._engine.observation(0, robot)

    def digest(self) -> int:
        """The match's state digest (every pose, belief and random draw)."""
        self._check_started()
        return self._engine.digest(0)

    def truth(self) -> dict:
        """The match's ground truth: tick, every robot's pose, frozen flag and scan, every
        opponent's pose and tagged flag. For rendering and analysis; no observation reads
        it."""
        self._check_started()
        return self._setup.truth(0)

    def render(self):
        """With ``render_mode="rgb_array"``, an (H, W, 3) uint8 frame of the match's truth."""
        if self.render_mode is None:
            import gymnasium

            gymnasium.logger.warn("render() without a render_mode; pass render_mode='rgb_array'")
            return None
        if self._renderer is None:
            self._renderer = Renderer(self.map_def, self._ppm)
        if not self._started:
            return self._renderer.background.copy()
        return self._renderer.frame(self.truth())

    def close(self) -> None:
        """Ends the episode; idempotent (the engine holds no outside resource)."""
        self._closed = True
        self.agents = []

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("the environment is closed")

    def _check_started(self) -> None:
        self._check_open()
        if not self._started:
            raise RuntimeError("no match yet: call reset()")


class LasertagVectorEnv(VectorEnv):
    """``num_envs`` lasertag worlds stepped in one call, as a Gymnasium ``VectorEnv`` whose
    entries are robots: entry ``w * robots + r`` is robot ``r`` of world ``w`` (PettingZoo's
    per-agent view, as SuperSuit's Markov vector environments). So ``self.num_envs`` is
    worlds × robots; ``self.num_worlds`` is the worlds.

    Actions are a (num_envs, 3) array; ``step`` returns observations (num_envs, size)
    float32, rewards (num_envs,) float64, terminations and truncations (num_envs,) bool
    (the same for every robot of a world) and an empty ``infos``. A world whose episode
    ended starts its next one on the following step (``AutoresetMode.NEXT_STEP``): that
    step ignores its actions and returns its first observations with rewards 0.

    Seeds: world ``w``'s first episode has seed ``seed + w``, its later ones seeds drawn
    from a stream seeded by that; ``reset(seed=s)`` starts over from ``s``.
    ``episode_seeds`` gives each world's current seed, so any episode can be replayed in
    a :class:`NativeParallelEnv` or on a server.

    ``copy=False`` returns the engine's own arrays (no copy per step; the next step
    overwrites them). ``planner="coordinated"`` or ``"baseline"`` has the paper's planners
    drive the robots instead of the actions (which are then ignored): their episodes,
    rewards and capture times in the same harness as a learned policy's.
    ``planner="policy:<name>"`` has a shipped trained policy drive them the same way (its
    orders every 2 ticks, as a server's match gives them, whatever ``ticks_per_step``); only
    the policies built into the package run in-process (``"policy:learned"``), and a name
    that is not one is refused with a ValueError naming them.
    """

    metadata = {
        "autoreset_mode": AutoresetMode.NEXT_STEP,
        "render_modes": [],
    }

    def __init__(
        self,
        num_envs: int = 8,
        map: str | dict = "office",
        robots: int = 2,
        opponents: int = 1,
        seed: int = 0,
        opponent_bot: str = "wander",
        max_steps: int | None = 1200,
        ticks_per_step: int = 1,
        time_limit_s: float | None = None,
        placement: str | None = None,
        detections: int | None = None,
        rewards: dict | None = None,
        match_settings: dict | None = None,
        team_tracker: bool = True,
        copy: bool = True,
        planner: str = "api",
    ):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs: {num_envs!r} must be a positive integer")
        _check(
            robots=robots, opponents=opponents, ticks_per_step=ticks_per_step, seed=seed,
            max_steps=max_steps, detections=detections, render_mode=None, render_modes=[],
            rewards=rewards, match_settings=match_settings, map=map,
            time_limit_s=time_limit_s, rules=SHIPPED,
        )
        # The worlds' robots share one budget (memory grows with them: docs/research.md,
        # "Bounds"), checked before the engine builds any world.
        most = _native.BOUNDS["agents"]
        if num_envs * robots > most:
            raise ValueError(
                f"num_envs: {num_envs} worlds of {robots} robots are {num_envs * robots} "
                f"robots, at most {most} in one vector (num_envs ≤ {most // robots})"
            )
        self._setup = _Setup(
            worlds=int(num_envs), map=map, robots=robots, opponents=opponents, seed=seed,
            opponent_bot=opponent_bot, max_steps=max_steps, ticks_per_step=ticks_per_step,
            render_mode=None, render_modes=[], time_limit_s=time_limit_s,
            placement=placement, detections=detections, rewards=rewards,
            match_settings=match_settings, team_tracker=team_tracker, planner=planner,
        )
        self._engine = self._setup.engine
        self.layout = self._setup.layout
        self.map_def = self._setup.map_def
        self.num_worlds = int(num_envs)
        self.robots = robots
        self.num_envs = self.num_worlds * robots
        self.copy = copy
        self.single_observation_space = self.layout.space()
        self.single_action_space = action_space()
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.agent_ids = [(w, f"r{r}") for w in range(self.num_worlds) for r in range(robots)]
        w, size = self.num_worlds, self.layout.size
        self._obs = np.zeros((w, robots, size), dtype=np.float32)
        self._act = np.zeros((w, robots, 3), dtype=np.float32)
        self._rew = np.zeros((w, robots), dtype=np.float64)
        self._term = np.zeros(w, dtype=bool)
        self._trunc = np.zeros(w, dtype=bool)
        self._seed = int(seed)
        self._reset_done = False

    @property
    def episode_seeds(self) -> list[int]:
        """Each world's current episode seed."""
        return self._engine.seeds

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        """Starts every world's next episode. ``seed``: an int starts the seed streams over
        (world ``w``'s episode gets ``seed + w``); a list gives each world's seed (one per
        world, not per entry); None goes on with each world's stream (the constructor's
        ``seed`` the first time)."""
        seeds = None
        if isinstance(seed, (list, tuple, np.ndarray)):
            seeds = [int(s) for s in seed]
            if len(seeds) != self.num_worlds:
                raise ValueError(
                    f"seed: {len(seeds)} seeds, one per world is {self.num_worlds}"
                )
            for s in seeds:
                check_seed(s)
            base = None
        elif seed is not None:
            check_seed(seed)
            self._seed = int(seed)
            base = self._seed
        else:
            base = None if self._reset_done else self._seed
        self._engine.reset_all(self._obs, base, seeds)
        self._reset_done = True
        obs = self._obs.reshape(self.num_envs, -1)
        return (obs.copy() if self.copy else obs), {}

    def step(self, actions):
        if not self._reset_done:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(actions)
        if a.shape != (self.num_envs, 3):
            raise ValueError(f"actions: shape {a.shape}, the vector needs ({self.num_envs}, 3)")
        np.copyto(self._act, a.reshape(self._act.shape), casting="same_kind")
        self._engine.step_all(self._act, self._obs, self._rew, self._term, self._trunc)
        n = self.num_envs
        obs = self._obs.reshape(n, -1)
        rew = self._rew.reshape(n)
        term = np.repeat(self._term, self.robots)
        trunc = np.repeat(self._trunc, self.robots)
        if self.copy:
            obs, rew = obs.copy(), rew.copy()
        return obs, rew, term, trunc, {}

    def teacher_actions(self) -> np.ndarray:
        """With ``planner="coordinated"``, ``"search"`` or ``"baseline"``: each robot's
        action (num_envs, 3: forward, turn, and tag as 1.0 or 0.0) as its planner decided it
        at the end of the last :meth:`step`, from the state that step's observations
        describe; the robot carries it out on the next tick. Behaviour cloning pairs those
        observations with these actions. Zeros after ``reset`` and for an episode's first
        observations (nothing decided yet). A ValueError when actions drive the robots."""
        out = np.zeros((self.num_worlds, self.robots, 3), dtype=np.float32)
        self._engine.teacher_actions(out)
        return out.reshape(self.num_envs, 3)

    def world_digest(self, world: int) -> int:
        """World ``world``'s state digest."""
        return self._engine.digest(world)

    def world_truth(self, world: int) -> dict:
        """World ``world``'s ground truth (as :meth:`NativeParallelEnv.truth`)."""
        return self._setup.truth(world)

    def close_extras(self, **kwargs):
        pass


def vector_env(num_envs: int = 8, **kwargs) -> LasertagVectorEnv:
    """``num_envs`` in-process worlds as one Gymnasium ``VectorEnv`` of their robots; the
    keywords are :func:`lasertag_env.parallel_env`'s (without ``server``) plus ``copy``.
    See :class:`LasertagVectorEnv`."""
    return LasertagVectorEnv(num_envs=num_envs, **kwargs)
