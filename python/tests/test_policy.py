"""A shipped trained policy driving the team in-process (``planner="policy:<name>"``): its
episodes are a function of the seed alone (the actions are not read), and names that are
no shipped policy, or teams it would share with agents, are refused clearly.

Nothing here depends on what the shipped model learned: only that it runs, the same way
every time."""

from __future__ import annotations

import numpy as np
import pytest

import lasertag_env

KWARGS = dict(planner="policy:learned", ticks_per_step=4, max_steps=60)


def episode_ends(seeds, steps, actions):
    """Each world's episode ends over ``steps`` steps: (step, tick, terminated) of each,
    the tick read from the world before its auto-reset; and each world's final digest."""
    v = lasertag_env.vector_env(len(seeds), **KWARGS)
    v.reset(seed=list(seeds))
    ends = [[] for _ in seeds]
    for k in range(steps):
        _, rew, term, trunc, _ = v.step(actions(k, v.num_envs))
        assert np.isfinite(rew).all()
        for w in range(len(seeds)):
            if term[2 * w] or trunc[2 * w]:
                ends[w].append((k, v.world_truth(w)["tick"], bool(term[2 * w])))
    return ends, [v.world_digest(w) for w in range(len(seeds))]


def test_a_shipped_policy_drives_the_team_the_same_way_for_the_same_seed():
    zero = lambda k, n: np.zeros((n, 3), np.float32)  # noqa: E731
    rng = np.random.default_rng(1)
    table = rng.uniform(-1, 1, size=(200, 6, 3)).astype(np.float32)
    noise = lambda k, n: table[k]  # noqa: E731
    ends, digests = episode_ends([3, 3, 8], 130, zero)
    # Every world's episodes ended (a capture, or max_steps), the two worlds of seed 3 at
    # the same ticks, as another vector's worlds of that seed whatever actions it is given:
    # the policy drives, and its robots do not read the actions.
    assert all(len(e) >= 2 for e in ends), ends
    assert ends[0] == ends[1] and digests[0] == digests[1]
    again, again_digests = episode_ends([3, 3, 8], 130, noise)
    assert (again, again_digests) == (ends, digests)
    # The policy's robots moved: a stand-still team's world of the same seed differs.
    still = lasertag_env.vector_env(1, ticks_per_step=4, max_steps=60)
    still.reset(seed=[3])
    v = lasertag_env.vector_env(1, **KWARGS)
    v.reset(seed=[3])
    for _ in range(20):
        still.step(np.zeros((2, 3), np.float32))
        v.step(np.zeros((2, 3), np.float32))
    moved = [(r["x"], r["y"], r["theta"]) for r in v.world_truth(0)["robots"]]
    stood = [(r["x"], r["y"], r["theta"]) for r in still.world_truth(0)["robots"]]
    assert moved != stood


def test_unknown_policies_and_policies_beside_agents_are_refused():
    with pytest.raises(ValueError, match=r"policy:nope.*shipped.*policy:learned"):
        lasertag_env.vector_env(1, planner="policy:nope")
    with pytest.raises(ValueError, match="whole team"):
        lasertag_env.vector_env(1, planner=["policy:learned", "api"])
    # A team the policy drives has no agents, as one the built-in planner drives.
    with pytest.raises(ValueError, match="no agents"):
        lasertag_env.parallel_env(planner="policy:learned")
    with pytest.raises(ValueError, match="whole team"):
        lasertag_env.parallel_env(robots=2, planner=["policy:learned", "api"])


def test_over_http_a_policy_team_has_no_agents_either(server):
    with pytest.raises(ValueError, match="no agents"):
        lasertag_env.parallel_env(server=server, planner="policy:learned")
