"""The PettingZoo environment: PettingZoo's own checks, determinism, episodes' ends,
reset and close, rendering and refused arguments."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

import lasertag_env
from lasertag_env import policies


def test_pettingzoo_parallel_api(make_env):
    env = make_env(max_steps=60)
    parallel_api_test(env, num_cycles=80)


def test_pettingzoo_parallel_seed(server):
    # The test closes both environments itself; max_steps bounds its episode (PettingZoo
    # before 1.25 takes no num_cycles).
    parallel_seed_test(lambda: lasertag_env.parallel_env(server=server, max_steps=40))


def run_episode(env, seed, policy):
    """Observations, rewards and ends of one episode as bytes and tuples, for equality."""
    trace = []
    obs, infos = env.reset(seed=seed) if seed is not None else env.reset()
    trace.append(tuple(obs[a].tobytes() for a in env.possible_agents))
    raws = {a: infos[a]["observation"] for a in infos}
    while env.agents:
        actions = {a: policy(a, raws[a]) for a in env.agents}
        obs, rew, term, trunc, infos = env.step(actions)
        raws = {a: infos[a]["observation"] for a in infos}
        trace.append((
            tuple(obs[a].tobytes() for a in env.possible_agents),
            tuple(rew[a] for a in env.possible_agents),
            tuple(term[a] for a in env.possible_agents),
            tuple(trunc[a] for a in env.possible_agents),
            tuple(infos[a]["tick"] for a in env.possible_agents),
        ))
    return trace


def sampled(env):
    """A policy sampling each agent's action space (seeded, so two environments agree)."""
    for i, a in enumerate(env.possible_agents):
        env.action_space(a).seed(1000 + i)
    return lambda agent, raw: env.action_space(agent).sample()


def hunter(agent, raw):
    return policies.hunter(raw)


def test_same_seed_same_actions_identical_episodes(make_env):
    a = make_env(max_steps=300, ticks_per_step=2)
    b = make_env(max_steps=300, ticks_per_step=2)
    # Whole episodes: one that the hand policy wins (a tag ends it) and random ones that
    # run to max_steps, including resets without a seed, which draw the same seeds.
    for seed in (3, 11, None):
        ta = run_episode(a, seed, hunter)
        tb = run_episode(b, seed, hunter)
        assert ta == tb, f"seed {seed}: the episodes differ"
        if seed == 3:
            assert ta[-1][2] == (True, True), "seed 3 is meant to end with a tag"
    ta = run_episode(a, 5, sampled(a))
    tb = run_episode(b, 5, sampled(b))
    assert ta == tb
    assert len(ta) == 301


def test_a_small_team_tracker_changes_only_the_belief_parts(make_env):
    # The environment runs the team tracker at its default size (as a served team's) unless
    # told otherwise; at its minimum only the belief parts of the observation change.
    small = make_env(max_steps=400, team_tracker=False)
    full = make_env(max_steps=400)
    assert "tracker" not in full._create and small._create["tracker"]["particles_per_role"] == 10
    # Seed 3: the robots search, see the opponent and tag it (the episode ends on the tag).
    a, b = run_episode(small, 3, hunter), run_episode(full, 3, hunter)
    assert a[-1][2] == (True, True) and len(a) == len(b)
    belief = slice(small.layout.slices["belief_grid"].start, small.layout.size)
    differ = 0
    for i, (x, y) in enumerate(zip(a, b)):
        assert i == 0 or x[1:] == y[1:]  # rewards, ends, ticks
        for bx, by in zip(x if i == 0 else x[0], y if i == 0 else y[0]):
            ox, oy = np.frombuffer(bx, np.float32), np.frombuffer(by, np.float32)
            assert ox[: belief.start].tobytes() == oy[: belief.start].tobytes()
            differ += ox[belief].tobytes() != oy[belief].tobytes()
    assert differ > 0


def test_packed_scans_change_nothing(make_env):
    # The server's scans in hex (the default when it offers them) and as JSON numbers give
    # the same vectors and the same raw observations in infos, bit for bit.
    packed = make_env(max_steps=150)
    numbers = make_env(max_steps=150, packed_scans=False)
    assert packed._packed_scans and b'"scans":"hex"' in packed._act_body({})
    assert not numbers._packed_scans and b"scans" not in numbers._act_body({})
    for env in (packed, numbers):
        env.reset(seed=3)
    steps = 0
    while packed.agents:
        actions = {a: packed.action_space(a).sample() for a in packed.agents}
        a = packed.step(actions)
        b = numbers.step(actions)
        for agent in packed.possible_agents:
            assert a[0][agent].tobytes() == b[0][agent].tobytes()
            assert a[4][agent]["observation"] == b[4][agent]["observation"]
        assert a[1:4] == b[1:4]
        steps += 1
    assert steps == 150 and not numbers.agents


def test_different_seeds_differ(make_env):
    env = make_env(max_steps=20, placement="random")
    t1 = run_episode(env, 1, hunter)
    t2 = run_episode(env, 2, hunter)
    assert t1 != t2


def test_capture_terminates_with_the_tag_reward(make_env):
    env = make_env(max_steps=600, seed=3)
    obs, infos = env.reset()
    raws = {a: infos[a]["observation"] for a in infos}
    total = dict.fromkeys(env.possible_agents, 0.0)
    while env.agents:
        obs, rew, term, trunc, infos = env.step({a: policies.hunter(raws[a]) for a in env.agents})
        raws = {a: infos[a]["observation"] for a in infos}
        for a in rew:
            total[a] += rew[a]
    assert all(term.values()) and not any(trunc.values())
    assert infos["r0"]["winner"] == "robots" and infos["r0"]["reason"] == "all_tagged"
    tagger = [a for a in env.possible_agents if any(
        e["kind"] == "tag" and e["by"] == a for e in env.last_events)]
    assert len(tagger) == 1
    steps = env.steps
    assert total[tagger[0]] == pytest.approx(1.0 - 0.001 * steps)
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})


def test_max_steps_and_time_limit_truncate(make_env):
    env = make_env(max_steps=7)
    env.reset(seed=1)
    for i in range(7):
        _, _, term, trunc, _ = env.step({})
    assert all(trunc.values()) and not any(term.values()) and env.agents == []
    assert env.tick == 7

    env = make_env(max_steps=None, time_limit_s=1, ticks_per_step=6)
    env.reset(seed=1)
    steps = 0
    while env.agents:
        obs, rew, term, trunc, infos = env.step({})
        steps += 1
    assert steps == 4 and env.tick == 20  # 6 + 6 + 6 + the 2 left
    assert all(trunc.values()) and not any(term.values())
    assert infos["r1"]["reason"] == "time_limit" and infos["r1"]["winner"] == "opponents"
    assert rew["r0"] == pytest.approx(-0.002)


def test_observations_fit_the_space_and_layout(make_env):
    env = make_env(robots=3, opponents=2, max_steps=30)
    assert env.possible_agents == ["r0", "r1", "r2"]
    obs, infos = env.reset(seed=4)
    space = env.observation_space("r1")
    assert space.shape == (181 + 4 + 1 + 2 + 1 + 3 * 2 + 9 * 2 + 16 + 8 + 7 * 2 + 1,)
    assert env.observation_space("r1") is space
    parts = env.layout.decode(obs["r1"])
    raw = infos["r1"]["observation"]
    assert np.allclose(parts["scan"], np.asarray(raw["scan"]) / 8.0)
    assert parts["pose"][0] == pytest.approx(raw["estimate"]["x"] / 24.0)
    # r1's teammates are r0 and r2, both delivered by the perfect radio.
    mates = parts["teammates"].reshape(2, 9)
    assert mates[:, 0].tolist() == [1.0, 1.0]
    assert mates[0, 1] == pytest.approx(infos["r0"]["observation"]["estimate"]["x"] / 24.0, abs=1e-3)
    # The belief's parts are the server's, copied as they are.
    belief = raw["belief"]
    assert parts["belief_paths"].tolist() == pytest.approx(belief["paths"], abs=1e-6)
    assert sum(belief["paths"]) <= sum(belief["grid"]) + 1e-3
    for _ in range(30):
        obs, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})
        for a in obs:
            assert obs[a] in space and obs[a].dtype == np.float32


def test_reset_replaces_the_match_and_close_deletes_it(make_env, server):
    env = make_env(max_steps=10)
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})
    env.reset(seed=1)
    first = env.match_id
    env.step({})
    env.reset(seed=1)
    assert env.match_id != first and env.tick == 0
    client = lasertag_env.client.Client(server.url, server.admin_token)
    with pytest.raises(lasertag_env.ServerError) as gone:
        client.call("GET", f"/api/matches/{first}")
    assert gone.value.status == 404
    second = env.match_id
    env.close()
    env.close()  # idempotent
    with pytest.raises(lasertag_env.ServerError):
        client.call("GET", f"/api/matches/{second}")
    with pytest.raises(RuntimeError, match="closed"):
        env.reset()
    client.close()


def test_render_rgb_array(make_env):
    env = make_env(render_mode="rgb_array", max_steps=10)
    env.reset(seed=2)
    frame = env.render()
    assert frame.shape == (16 * 20, 24 * 20, 3) and frame.dtype == np.uint8
    for _ in range(10):
        env.step({a: np.array([1.0, 0.3, 0.0], dtype=np.float32) for a in env.agents})
    later = env.render()
    assert later.shape == frame.shape and not np.array_equal(later, frame)
    small = make_env(render_mode="rgb_array", pixels_per_metre=5)
    small.reset()
    assert small.render().shape == (80, 120, 3)
    quiet = make_env()
    quiet.reset()
    with pytest.warns(UserWarning, match="render_mode"):
        assert quiet.render() is None


def test_bad_arguments_are_refused_clearly(make_env, server):
    with pytest.raises(ValueError, match=r"unknown map 'nowhere'.*office"):
        make_env(map="nowhere")
    with pytest.raises(ValueError, match=r"robots: 9 must be in 1..=8"):
        make_env(robots=9)
    with pytest.raises(ValueError, match="render_mode"):
        make_env(render_mode="human")
    with pytest.raises(ValueError, match="rewards"):
        make_env(rewards={"tagg": 1})
    with pytest.raises(ValueError, match="match_settings"):
        make_env(match_settings={"planner": "coordinated"})
    env = make_env(opponent_bot="sleepy")
    # The server judges what it alone knows (bot names, settings), naming the field.
    with pytest.raises(ValueError, match="opponent_bot"):
        env.reset()
    env = make_env(match_settings={"tracker": {"particles_per_role": 1}})
    with pytest.raises(ValueError, match="particles_per_role"):
        env.reset()
    env = make_env()
    with pytest.raises(KeyError, match="r7"):
        env.action_space("r7")
    env.reset()
    with pytest.raises(ValueError, match="action of r1"):
        env.step({"r0": [0, 0, 0], "r1": [1.0, 0.5]})


def test_no_server_there():
    with pytest.raises(ConnectionRefusedError, match="no lasertag server"):
        # Port 9 (discard) on loopback: nothing listens there on a test machine.
        lasertag_env.parallel_env(server="http://127.0.0.1:9")


def test_missing_binary_is_named(monkeypatch, tmp_path):
    monkeypatch.setenv("LASERTAG_BIN", str(tmp_path / "lasertag"))
    with pytest.raises(lasertag_env.BinaryNotFound, match="LASERTAG_BIN"):
        lasertag_env.parallel_env(server="local")


def test_own_server_starts_and_stops():
    env = lasertag_env.parallel_env(server="local", max_steps=5)
    own = env._owned_server
    assert own is not None and own.running()
    env.reset(seed=1)
    env.step({})
    env.close()
    assert not own.running()


def test_own_server_stops_at_interpreter_exit(tmp_path):
    import os
    import subprocess
    import sys
    import time

    script = (
        "import lasertag_env\n"
        "env = lasertag_env.parallel_env(server='local')\n"
        "env.reset()\n"
        "print(env._owned_server.pid, flush=True)\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         timeout=120, check=True)
    pid = int(out.stdout.split()[-1])
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.1)
    pytest.fail(f"server {pid} still runs after its interpreter exited")


def test_without_the_admin_token_owner_tokens_and_rate_limits(monkeypatch):
    # A server with a tight per-address rate: the environment, holding only its matches'
    # owner tokens, waits out each 429 and sends the step again, and no step is applied
    # twice (the tick count says so).
    monkeypatch.delenv("LASERTAG_ADMIN_TOKEN", raising=False)
    with lasertag_env.LocalServer(env={"LASERTAG_REQUESTS_PER_S": "40",
                                       "LASERTAG_REQUEST_BURST": "8"}) as strict:
        env = lasertag_env.parallel_env(server=strict.url, max_steps=None)
        try:
            assert env._client.token is None
            env.reset(seed=1)
            for _ in range(12):
                env.step({})
            assert env.tick == 12
        finally:
            env.close()
