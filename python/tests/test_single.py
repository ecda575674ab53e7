"""The Gymnasium single-robot environment."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import lasertag_env


def test_gymnasium_check_env(server):
    env = lasertag_env.single_agent_env(server=server, max_steps=30, render_mode="rgb_array")
    try:
        check_env(env, skip_render_check=False)
    finally:
        env.close()


def test_make_and_episode_with_hunting_teammate(server):
    env = gymnasium.make("lasertag/Lasertag-v0", server=server, others="hunter",
                         max_steps=600, seed=3)
    try:
        obs, info = env.reset()
        assert obs.shape == env.observation_space.shape
        total, steps, done = 0.0, 0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(np.zeros(3, dtype=np.float32))
            total += reward
            steps += 1
            done = terminated or truncated
        # r0 stands still; its teammate r1 hunts, and the tag ends the match. r0 earns
        # only the time cost (no shared credit by default).
        assert terminated and info["winner"] == "robots"
        assert total == pytest.approx(-0.001 * env.unwrapped.par.tick)
    finally:
        env.close()


def test_single_render_and_arguments(server):
    env = lasertag_env.single_agent_env(robot=1, server=server, render_mode="rgb_array")
    try:
        env.reset(seed=0)
        frame = env.render()
        assert frame.shape == (320, 480, 3) and frame.dtype == np.uint8
        assert env.agent == "r1"
    finally:
        env.close()
    with pytest.raises(ValueError, match="robot 2"):
        lasertag_env.single_agent_env(robot=2, server=server)
    with pytest.raises(ValueError, match="others"):
        lasertag_env.single_agent_env(others="chaser", server=server)
