"""A Gymnasium environment that controls one robot of the team.

The other robots (if the team has more than one) follow a fixed policy: ``"idle"`` (stand
still; the default), ``"hunter"`` (the hand-written policy of ``lasertag_env.policies``) or
any callable from a robot's raw observation to an action. Everything else (spaces,
rewards, episode ends, determinism) is the parallel environment's, for that robot.
"""

from __future__ import annotations

from typing import Any, Callable

import gymnasium

from . import policies
from .parallel import TICK_HZ, parallel_env

__all__ = ["LasertagEnv", "single_agent_env"]

Policy = Callable[[dict], Any]


class LasertagEnv(gymnasium.Env):
    """Robot ``r{robot}`` of a lasertag match as a Gymnasium environment.

    Keyword arguments other than ``robot``, ``others`` and ``render_mode`` are the
    parallel environment's (``server``, ``map``, ``robots``, ``opponents``, ``seed``,
    ``max_steps``, ``ticks_per_step``, …; see :func:`lasertag_env.parallel_env`).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": TICK_HZ}

    def __init__(
        self,
        robot: int = 0,
        others: str | Policy = "idle",
        render_mode: str | None = None,
        **kwargs,
    ):
        if isinstance(others, str):
            if others not in ("idle", "hunter"):
                raise ValueError(f"others {others!r}: 'idle', 'hunter' or a callable")
            others = getattr(policies, others)
        elif not callable(others):
            raise TypeError("others must be 'idle', 'hunter' or a callable")
        self._others = others
        self.par = parallel_env(render_mode=render_mode, **kwargs)
        robots = len(self.par.possible_agents)
        if not 0 <= robot < robots:
            self.par.close()
            raise ValueError(f"robot {robot} must be in 0..{robots - 1}: the team has {robots} robots")
        self.agent = f"r{robot}"
        self.render_mode = render_mode
        self.observation_space = self.par.observation_space(self.agent)
        self.action_space = self.par.action_space(self.agent)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs, infos = self.par.reset(seed=seed, options=options)
        return obs[self.agent], infos[self.agent]

    def step(self, action):
        actions = {self.agent: action}
        if self._others is not policies.idle:
            for a in self.par.possible_agents:
                if a != self.agent:
                    actions[a] = self._others(self.par.raw_observation(a))
        obs, rewards, terms, truncs, infos = self.par.step(actions)
        a = self.agent
        return obs[a], float(rewards[a]), bool(terms[a]), bool(truncs[a]), infos[a]

    def render(self):
        return self.par.render()

    def close(self):
        self.par.close()

    @property
    def layout(self):
        """The observation vector's layout (``layout.slices``, ``layout.decode``)."""
        return self.par.layout


def single_agent_env(
    robot: int = 0, others: str | Policy = "idle", render_mode: str | None = None, **kwargs
) -> LasertagEnv:
    """A Gymnasium environment controlling robot ``r{robot}``; see :class:`LasertagEnv`."""
    return LasertagEnv(robot=robot, others=others, render_mode=render_mode, **kwargs)
