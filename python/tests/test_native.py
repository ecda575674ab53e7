"""The in-process backend: the same episodes as the HTTP backend bit for bit, PettingZoo's
checks, the vector environment (shapes, auto-reset, seeds) and refused arguments."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

import lasertag_env
from lasertag_env import policies


def episode_digest(env, seed, policy, steps=None):
    """A digest of one whole episode (every observation's bytes, reward, end flag and
    tick) and its length; ``policy(agent, raw_observation, step)`` chooses the actions."""
    h = hashlib.sha256()
    obs, _ = env.reset(seed=seed) if seed is not None else env.reset()
    for a in env.possible_agents:
        h.update(obs[a].tobytes())
    n = 0
    while env.agents and (steps is None or n < steps):
        actions = {a: policy(a, env.raw_observation(a), n) for a in env.agents}
        obs, rew, term, trunc, infos = env.step(actions)
        n += 1
        for a in env.possible_agents:
            h.update(obs[a].tobytes())
            h.update(np.float64(rew[a]).tobytes())
            h.update(bytes([term[a], trunc[a]]))
            h.update(int(infos[a]["tick"]).to_bytes(8, "little"))
    return h.hexdigest(), n


def scripted(seed):
    """Actions from a seeded stream (the same for both backends), tagging now and then;
    float32 like a policy's output, plus out-of-range and NaN values that both clip."""
    rng = np.random.default_rng(seed)
    table = rng.uniform(-1.3, 1.3, size=(4096, 8, 3)).astype(np.float32)
    table[::97, :, 0] = np.nan

    def policy(agent, raw, n):
        return table[n % 4096, int(agent[1:])]
    return policy


def hunter(agent, raw, n):
    return policies.hunter(raw)


CASES = [
    # The default match, a tag that ends it, and a random one that runs out of steps.
    (dict(max_steps=300, ticks_per_step=2), 3, hunter),
    (dict(max_steps=120), 5, scripted(5)),
    # Evade bots, more opponents than detection slots, a lossy radio (teammates' ages),
    # dead reckoning, random starts, team reward, no max_steps (time fraction of the limit).
    (dict(opponents=3, opponent_bot="evade", detections=2, max_steps=None, time_limit_s=6,
          placement="random", rewards={"team_tag": 0.5},
          match_settings={"radio": {"latency_ticks": 3, "loss": 0.3},
                          "localisation": False}), 8, scripted(8)),
    (dict(map="warehouse", robots=3, ticks_per_step=3, max_steps=80), 13, hunter),
    # A mixed team: r0 coordinated, the policy drives r1 and r2.
    (dict(robots=3, opponents=2, planner=["coordinated", "api", "api"], max_steps=150,
          team_tracker=True), 21, scripted(21)),
]


@pytest.mark.parametrize("kwargs,seed,policy", CASES)
def test_both_backends_give_the_same_episodes(server, kwargs, seed, policy):
    native = lasertag_env.parallel_env(**kwargs)
    http = lasertag_env.parallel_env(server=server, **kwargs)
    try:
        assert type(native).__name__ == "NativeParallelEnv"
        for s in (seed, None):  # a seeded reset, then one drawing its seed
            dn, n = episode_digest(native, s, policy)
            dh, m = episode_digest(http, s, policy)
            assert (dn, n) == (dh, m), f"seed {s}: the backends' episodes differ"
            assert n > 0
            first = native.possible_agents[0]
            assert native.raw_observation(first) == http.raw_observation(first)
    finally:
        native.close()
        http.close()


@pytest.mark.parametrize("backend", ["native", "http"])
def test_a_mixed_teams_agents_are_its_api_robots(server, backend):
    kwargs = dict(robots=2, planner=["coordinated", "api"], max_steps=40)
    env = lasertag_env.parallel_env(**kwargs, **({"server": server} if backend == "http" else {}))
    try:
        assert env.possible_agents == ["r1"]
        obs, _ = env.reset(seed=4)
        assert list(obs) == ["r1"]
        start = env.truth()["robots"][0]
        for _ in range(40):
            if not env.agents:
                break
            env.step({"r1": np.array([0.0, 0.0, 0.0], dtype=np.float32)})
        # r0 is the team's planner's: it went somewhere on its own.
        moved = env.truth()["robots"][0]
        assert (moved["x"], moved["y"]) != (start["x"], start["y"])
        with pytest.raises(KeyError):
            env.raw_observation("r0")
    finally:
        env.close()
    for bad, why in ((["coordinated", "baseline"], "share one planner"),
                     (["coordinated"], "each of the 2 robots"),
                     ("coordinated", "no agents"),
                     (["coordinated", "coordinated"], "no robot is 'api'")):
        with pytest.raises(ValueError, match=why):
            lasertag_env.parallel_env(robots=2, planner=bad)


def test_a_hunting_episode_ends_in_a_tag_in_process():
    env = lasertag_env.parallel_env(max_steps=300, ticks_per_step=2)
    env.reset(seed=3)
    while env.agents:
        obs, rew, term, trunc, infos = env.step(
            {a: policies.hunter(env.raw_observation(a)) for a in env.agents}
        )
    assert term == {"r0": True, "r1": True}
    assert infos["r0"]["winner"] == "robots" and infos["r0"]["reason"] == "all_tagged"
    assert sum(i["tags"] for i in infos.values()) == 1
    assert max(rew.values()) > 0.9  # the tag's reward


def test_pettingzoo_checks_in_process():
    parallel_api_test(lasertag_env.parallel_env(max_steps=60), num_cycles=80)
    parallel_seed_test(lambda: lasertag_env.parallel_env(max_steps=40))


def test_single_agent_env_in_process():
    from gymnasium.utils.env_checker import check_env

    env = lasertag_env.single_agent_env(max_steps=30, render_mode="rgb_array", others="hunter")
    check_env(env, skip_render_check=True)
    env.reset(seed=2)
    frame = env.render()
    assert frame.ndim == 3 and frame.dtype == np.uint8 and frame.any()
    env.close()


def test_vector_env_steps_every_world_and_resets_on_the_next_step():
    v = lasertag_env.vector_env(3, robots=2, max_steps=4)
    assert (v.num_worlds, v.num_envs) == (3, 6)
    obs, infos = v.reset(seed=10)
    assert obs.shape == (6, v.layout.size) and obs.dtype == np.float32
    assert v.observation_space.contains(obs)
    assert v.episode_seeds == [10, 11, 12]
    actions = np.tile(np.array([0.5, 0.2, 0.0], np.float32), (6, 1))
    for k in range(4):
        obs, rew, term, trunc, infos = v.step(actions)
        assert rew.shape == (6,) and rew.dtype == np.float64
        assert not term.any()
        assert trunc.all() == (k == 3)
    np.testing.assert_allclose(rew, -0.001)
    # The step after the end starts every world's next episode: its first observations,
    # no reward, no end, and a fresh seed from each world's stream.
    obs, rew, term, trunc, _ = v.step(actions)
    assert not (rew.any() or term.any() or trunc.any())
    assert obs[:, 181 + 7].max() == 0.0  # the time part starts again
    seeds = v.episode_seeds
    assert len(set(seeds)) == 3 and not set(seeds) & {10, 11, 12}


def test_each_vector_world_is_the_parallel_env_with_its_seed():
    robots, steps = 2, 50
    v = lasertag_env.vector_env(4, robots=robots, seed=20, max_steps=steps, copy=False)
    obs, _ = v.reset(seed=20)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(steps, 4 * robots, 3)).astype(np.float32)
    vec_trace = [obs.copy()]
    for k in range(steps):
        obs, rew, term, trunc, _ = v.step(actions[k])
        vec_trace.append(obs.copy())
    for w in (0, 3):
        env = lasertag_env.parallel_env(robots=robots, max_steps=steps)
        o, _ = env.reset(seed=20 + w)
        assert np.array_equal(np.stack([o[a] for a in env.possible_agents]),
                              vec_trace[0][w * robots:(w + 1) * robots])
        for k in range(steps):
            o, *_ = env.step({f"r{r}": actions[k][w * robots + r] for r in range(robots)})
            assert np.array_equal(np.stack([o[a] for a in env.possible_agents]),
                                  vec_trace[k + 1][w * robots:(w + 1) * robots]), f"world {w}, step {k}"


def test_vector_env_is_reproducible_and_seeds_differ():
    def run(seed):
        v = lasertag_env.vector_env(2, max_steps=30)
        v.reset(seed=seed)
        a = np.full((v.num_envs, 3), 0.7, np.float32)
        out = [v.step(a)[0] for _ in range(30)]
        return np.stack(out), [v.world_digest(w) for w in range(2)]
    a, da = run(1)
    b, db = run(1)
    c, dc = run(2)
    assert np.array_equal(a, b) and da == db
    assert not np.array_equal(a, c) and da != dc


def test_bad_arguments_are_refused_clearly():
    with pytest.raises(ValueError, match="unknown map 'atlantis'"):
        lasertag_env.parallel_env(map="atlantis")
    with pytest.raises(ValueError, match="tracker.particles: unknown setting"):
        lasertag_env.parallel_env(match_settings={"tracker": {"particles": 5}})
    with pytest.raises(ValueError, match="bounces: not a setting of the in-process engine"):
        lasertag_env.parallel_env(match_settings={"bounces": 1})
    with pytest.raises(ValueError, match="robots: 9 must be in 1..=8"):
        lasertag_env.parallel_env(robots=9)
    with pytest.raises(ValueError, match="map.width"):
        bad = lasertag_env.shipped_map("office")
        bad["width"] = -1
        lasertag_env.parallel_env(map=bad)
    with pytest.raises(ValueError, match=r"map.obstacles\[0\]"):
        bad = lasertag_env.shipped_map("office")
        bad["obstacles"][0] = [[1, 1], [2, 2]]
        lasertag_env.parallel_env(map=bad)
    with pytest.raises(TypeError, match="packed_scans is an argument of the HTTP backend"):
        lasertag_env.parallel_env(packed_scans=False)
    v = lasertag_env.vector_env(2)
    with pytest.raises(RuntimeError, match="reset"):
        v.step(np.zeros((4, 3), np.float32))
    v.reset()
    with pytest.raises(ValueError, match=r"actions: shape \(3, 3\), the vector needs \(4, 3\)"):
        v.step(np.zeros((3, 3), np.float32))
    with pytest.raises(ValueError, match="num_envs"):
        lasertag_env.vector_env(0)
    env = lasertag_env.parallel_env()
    with pytest.raises(RuntimeError, match="reset"):
        env.truth()
    env.reset(seed=1)
    with pytest.raises(ValueError, match="action of r1"):
        env.step({"r0": [0, 0, 0], "r1": [1.0, 0.5]})


def test_a_seed_per_world_and_the_papers_planners_in_the_same_harness():
    v = lasertag_env.vector_env(3, planner="coordinated", ticks_per_step=4, max_steps=400)
    v.reset(seed=[5, 5, 9])
    assert v.episode_seeds == [5, 5, 9]
    zero = np.zeros((v.num_envs, 3), np.float32)
    ended_at = [None] * 3
    for k in range(400):
        _, _, term, trunc, _ = v.step(zero)
        for w in range(3):
            if ended_at[w] is None and (term[2 * w] or trunc[2 * w]):
                ended_at[w] = (k, bool(term[2 * w]))
        if all(ended_at):
            break
    # The coordinated robots capture the wanderer on their own (the actions are ignored),
    # the same way for the same seed.
    assert all(e is not None and e[1] for e in ended_at), ended_at
    assert ended_at[0] == ended_at[1]
    with pytest.raises(ValueError, match="seed: 2 seeds, one per world is 3"):
        v.reset(seed=[1, 2])
    with pytest.raises(ValueError, match="planner"):
        lasertag_env.vector_env(1, planner="clever")


def test_the_planners_decisions_come_back_as_the_actions_that_give_them():
    # One tick a step: the teacher's action after step k, decided from step k's
    # observation, is the command that turns the robot during step k + 1.
    v = lasertag_env.vector_env(2, planner="coordinated", ticks_per_step=1, seed=11)
    v.reset()
    label = v.teacher_actions()
    assert not label.any()
    zero = np.zeros((v.num_envs, 3), np.float32)
    before = [v.world_truth(w)["robots"] for w in range(2)]
    turned = agreed = fired = 0
    for _ in range(300):
        _, _, term, trunc, _ = v.step(zero)
        after = [v.world_truth(w)["robots"] for w in range(2)]
        for w in range(2):
            for r in range(2):
                turn = label[2 * w + r, 1]
                if abs(turn) > 0.2 and not after[w][r]["frozen"]:
                    d = np.angle(np.exp(1j * (after[w][r]["theta"] - before[w][r]["theta"])))
                    turned += 1
                    agreed += int(np.sign(d) == np.sign(turn))
        before = after
        label = v.teacher_actions()
        assert label.shape == (v.num_envs, 3)
        assert np.all(np.abs(label[:, :2]) <= 1.0) and set(np.unique(label[:, 2])) <= {0.0, 1.0}
        fired += int(label[:, 2].sum())
        for w in range(2):
            if term[2 * w] or trunc[2 * w]:
                # The next step starts the world's next episode: nothing to compare.
                label[2 * w : 2 * w + 2] = 0.0
    assert turned > 20 and agreed == turned, (turned, agreed)
    assert fired > 0, "the planners fired at least once"
    with pytest.raises(ValueError, match="no built-in planner"):
        lasertag_env.vector_env(1).teacher_actions()


def test_the_engine_carries_every_shipped_map_as_the_server_reads_it():
    import json
    import pathlib

    maps = pathlib.Path(__file__).resolve().parents[2] / "maps"
    files = {p.stem: json.loads(p.read_text()) for p in maps.glob("*.json")}
    # native/lib.rs names the files it builds in: a map added to maps/ must be added there.
    assert set(lasertag_env.SHIPPED_MAPS) == set(files)
    for name, text in files.items():
        assert lasertag_env.shipped_map(name) == text
