"""What both backends' PettingZoo environments are alike in: the agents, their spaces and
the sequence of match seeds. :class:`~lasertag_env.parallel.LasertagParallelEnv` (HTTP)
and :class:`~lasertag_env.native.NativeParallelEnv` (in-process) build on it, which is
what keeps their episodes the same for the same seeds."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from .args import check_seed, unpack
from .observation import ObservationLayout
from .rules import SHIPPED

__all__ = ["TeamEnv", "action_space", "agent_robots", "is_policy"]


PLANNERS = ("api", "coordinated", "baseline")
#: ``planner="policy:<name>"``: a trained policy drives the whole team (in-process, the
#: shipped ones; over HTTP, any the server holds, which judges the name).
POLICY_PREFIX = "policy:"


def is_policy(planner) -> bool:
    """Whether ``planner`` names a trained policy (``"policy:<name>"``)."""
    return isinstance(planner, str) and planner.startswith(POLICY_PREFIX)


def agent_robots(robots: int, planner) -> list[int]:
    """The indices of the robots a policy drives: all with ``planner="api"``; with one
    planner per robot, those listed ``"api"`` (the others are the team's built-in planner's,
    which must be the same one). A ValueError names what is wrong."""
    if isinstance(planner, str):
        if is_policy(planner):
            raise ValueError(
                f"planner {planner!r}: a team the trained policy drives has no agents; "
                "measure it with vector_env(planner=...), whose episodes, rewards and ends "
                "it reports"
            )
        if planner != "api":
            raise ValueError(
                f"planner {planner!r}: a team the built-in planner drives has no agents; give "
                "one planner per robot, e.g. ['coordinated', 'api'], or measure it with "
                "vector_env(planner=...)"
            )
        return list(range(robots))
    names = list(planner)
    policy = next((n for n in names if is_policy(n)), None)
    if policy is not None:
        raise ValueError(
            f"planner {planner!r}: a trained policy drives the whole team; give "
            f"planner={policy!r} alone (to vector_env)"
        )
    if len(names) != robots or any(n not in PLANNERS for n in names):
        raise ValueError(
            f"planner {planner!r}: give one of {PLANNERS} for each of the {robots} robots"
        )
    built_in = {n for n in names if n != "api"}
    if len(built_in) > 1:
        raise ValueError(f"planner {planner!r}: the robots a team plans share one planner")
    agents = [i for i, n in enumerate(names) if n == "api"]
    if not agents:
        raise ValueError(f"planner {planner!r}: no robot is 'api', so the policy drives none")
    return agents


def action_space() -> spaces.Box:
    """A robot's action: forward and turn as fractions of the top speed and turn rate
    (counter-clockwise positive), and tag, which fires above 0.5."""
    return spaces.Box(
        np.array([-1.0, -1.0, 0.0], dtype=np.float32),
        np.array([1.0, 1.0, 1.0], dtype=np.float32),
        dtype=np.float32,
    )


class TeamEnv(ParallelEnv):
    """Robots ``r0 … r{n-1}`` as PettingZoo agents."""

    metadata = {
        "name": "lasertag_v0",
        "render_modes": ["rgb_array"],
        "render_fps": SHIPPED["tick_hz"],
        "is_parallelizable": True,
    }

    def _init_team(self, robots: int, layout: ObservationLayout, seed: int,
                   planner: str | list = "api") -> None:
        # The agents are the robots the policy drives: every one, or in a mixed team
        # (``planner=["coordinated", "api"]``) those listed ``"api"``, named by their ids.
        self._robots = agent_robots(robots, planner)
        self.possible_agents = [f"r{i}" for i in self._robots]
        self._agent_names = frozenset(self.possible_agents)
        self.layout = layout
        self._obs_spaces = {a: layout.space() for a in self.possible_agents}
        self._act_spaces = {a: action_space() for a in self.possible_agents}
        self._seed_rng = np.random.default_rng(seed)
        self._first_seed: int | None = seed
        self.episode_seed: int | None = None

    # The same space object every time for an agent (PettingZoo's API test checks it, and
    # seeding a space must stick), one per agent so that each samples its own stream.
    def observation_space(self, agent: str) -> spaces.Box:
        try:
            return self._obs_spaces[agent]
        except KeyError:
            raise KeyError(f"no agent {agent!r}; the agents are {self.possible_agents}") from None

    def action_space(self, agent: str) -> spaces.Box:
        try:
            return self._act_spaces[agent]
        except KeyError:
            raise KeyError(f"no agent {agent!r}; the agents are {self.possible_agents}") from None

    def _match_seed(self, seed: int | None) -> int:
        """The next episode's match seed: ``seed`` when given (which also seeds the draws
        after it); else the constructor's seed the first time; else a draw from a generator
        seeded by the last seed given, so unseeded resets are reproducible too."""
        if seed is not None:
            check_seed(seed)
            self._seed_rng = np.random.default_rng(seed)
            match_seed = int(seed)
        elif self._first_seed is not None:
            match_seed = self._first_seed
        else:
            match_seed = int(self._seed_rng.integers(0, 2**31))
        self._first_seed = None
        return match_seed

    def _team_actions(self, actions: dict):
        """Each agent in order with its action as (forward, turn, fires), clipped as
        :func:`~lasertag_env.args.unpack` does, or None for an agent left out (it stands
        still). A ValueError names an id that is no agent (a typo, or a robot the team's
        planner drives, would otherwise stand still unnoticed) and an agent whose action is
        not three numbers."""
        if not isinstance(actions, Mapping):
            raise TypeError(f"actions must be a dict from agent to action, not {type(actions).__name__}")
        if not self._agent_names.issuperset(actions):
            unknown = next(a for a in actions if a not in self._agent_names)
            raise ValueError(
                f"actions: no agent {unknown!r}; the agents are {self.possible_agents}"
            )
        for agent in self.possible_agents:
            a = actions.get(agent)
            if a is None:
                yield agent, None
                continue
            try:
                forward, turn, tag = unpack(a)
            except (TypeError, ValueError):
                raise ValueError(
                    f"action of {agent}: {a!r} is not three numbers (forward, turn, tag)"
                ) from None
            yield agent, (forward, turn, tag > 0.5)
