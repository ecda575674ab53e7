"""The in-process engine never aborts the interpreter: every count is bounded before
anything is allocated for it, NaN and infinities are refused, unknown agents and actions of
the wrong shape are refused, each with a Python exception naming what is wrong.

Calls that would abort the interpreter (SIGABRT, "memory allocation of N bytes failed") if
a count were allocated for before its bound was checked run in a child process with its
address space capped, so that a regression fails the test rather than killing pytest or
exhausting the machine's memory.
"""

from __future__ import annotations

import json
import math
import resource
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import lasertag_env
from lasertag_env import _native
from lasertag_env.rules import SHIPPED

# Far more than a refused call needs, far less than what the counts below would allocate.
ADDRESS_SPACE = 4 << 30


def _cap_memory():
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def outcomes(*calls: str) -> list[str]:
    """Runs each call in one child interpreter (after ``import lasertag_env`` and the
    names below) and returns what each did: ``accepted`` or ``Type: message``. The child
    must exit cleanly whatever the calls do."""
    prelude = textwrap.dedent(
        """
        import math
        import numpy as np
        import lasertag_env
        from lasertag_env import _native
        OFFICE = lasertag_env.shipped_map("office")

        def engine(settings=None, worlds=1, detections=1, beams=181, laser_range=8.0,
                   fov_deg=180.0, rewards=(1.0, 0.0, -0.001), ticks=1, max_steps=10):
            return _native.Engine(OFFICE, settings or {}, worlds, 0, max_steps, ticks,
                                  rewards, detections, beams, laser_range, fov_deg)
        """
    )
    body = "".join(
        textwrap.dedent(
            f"""
            try:
                {call}
            except Exception as e:
                print(type(e).__name__ + ": " + str(e).replace(chr(10), " "), flush=True)
            else:
                print("accepted", flush=True)
            """
        )
        for call in calls
    )
    p = subprocess.run(
        [sys.executable, "-c", prelude + body], capture_output=True, text=True,
        preexec_fn=_cap_memory, timeout=300,
    )
    assert p.returncode == 0, f"the child ended with {p.returncode}:\n{p.stdout}\n{p.stderr[-2000:]}"
    lines = p.stdout.splitlines()
    assert len(lines) == len(calls), p.stdout + p.stderr
    return lines


def test_counts_that_would_abort_the_interpreter_are_refused_first():
    got = outcomes(
        "lasertag_env.vector_env(10**6)",
        "lasertag_env.parallel_env(detections=10**9)",
        "lasertag_env.vector_env(2, detections=10**9)",
        "lasertag_env.parallel_env(robots=10**9)",
        "lasertag_env.vector_env(2, robots=10**9)",
        "lasertag_env.parallel_env(opponents=10**9)",
        # The raw engine, which the environments call: it checks every count itself.
        "engine(worlds=10**6)",
        "engine(detections=10**9)",
        "engine(settings={'robots': 10**9})",
        "engine(settings={'opponents': 10**9})",
        "engine(ticks=10**9)",
        "engine(beams=10**9)",
    )
    assert got[0].startswith("ValueError: num_envs: 1000000 worlds of 2 robots"), got[0]
    assert got[1] == "ValueError: detections: 1000000000 must be in 0..=32 (at most the " \
        "opponents a match may have)", got[1]
    assert got[2].startswith("ValueError: detections: 1000000000"), got[2]
    assert got[3] == "ValueError: robots: 1000000000 must be in 1..=8", got[3]
    assert got[4] == "ValueError: robots: 1000000000 must be in 1..=8", got[4]
    assert got[5] == "ValueError: opponents: 1000000000 must be in 1..=32", got[5]
    assert got[6] == "ValueError: worlds: 1000000 must be in 1..=16384", got[6]
    assert got[7] == "ValueError: detections: 1000000000 must be in 0..=32", got[7]
    assert got[8] == "ValueError: robots: 1000000000 must be in 1..=8", got[8]
    assert got[9] == "ValueError: opponents: 1000000000 must be in 1..=32", got[9]
    assert got[10] == "ValueError: ticks_per_step: 1000000000 must be in 1..=100000", got[10]
    assert got[11].startswith("ValueError: beams: 1000000000: the match's laser has 181"), got[11]


def test_the_worlds_share_one_budget_of_robots():
    most = _native.BOUNDS["agents"]
    over = most // 2 + 1
    got = outcomes(
        f"lasertag_env.vector_env({over}, robots=2)",
        f"engine(settings={{'robots': 2}}, worlds={over})",
        f"lasertag_env.vector_env(2, robots=8, opponents=32, detections=32).reset()",
    )
    assert got[0] == (
        f"ValueError: num_envs: {over} worlds of 2 robots are {2 * over} robots, at most "
        f"{most} in one vector (num_envs ≤ {most // 2})"
    ), got[0]
    assert got[1] == (
        f"ValueError: worlds: {over} worlds of 2 robots are {2 * over} robots, at most "
        f"{most} in one engine"
    ), got[1]
    # The largest worlds themselves (the budget itself is checked in the core's tests).
    assert got[2] == "accepted", got[2]


def test_nan_and_infinities_are_refused_for_every_float():
    got = outcomes(
        "lasertag_env.parallel_env(time_limit_s=float('nan'))",
        "lasertag_env.vector_env(2, time_limit_s=float('inf'))",
        "lasertag_env.parallel_env(match_settings={'time_limit_s': float('nan')})",
        "engine(settings={'time_limit_s': float('nan')})",
        "engine(beams=0)",
        "engine(laser_range=float('nan'))",
        "engine(fov_deg=float('inf'))",
        "engine(rewards=(float('nan'), 0.0, -0.001))",
        "engine(rewards=(1.0, 0.0, float('-inf')))",
        "engine(max_steps=0)",
        "engine(ticks=0)",
        "engine(settings={'robot_starts': [[2.0, 2.0, 1e300], [3.0, 3.0, 0.0]]})",
        "lasertag_env.parallel_env(rewards={'tag': float('nan')})",
        "lasertag_env.parallel_env(pixels_per_metre=float('nan'))",
        "lasertag_env.parallel_env(pixels_per_metre=1e6)",
        # Within the bounds still works.
        "lasertag_env.parallel_env(time_limit_s=86400, detections=32).reset()",
    )
    assert got[0] == "ValueError: time_limit_s: nan must be finite and in (0, 86400]", got[0]
    assert got[1] == "ValueError: time_limit_s: inf must be finite and in (0, 86400]", got[1]
    assert got[2] == "ValueError: time_limit_s: NaN must be finite and in (0, 86400]", got[2]
    assert got[3] == got[2]
    assert got[4].startswith("ValueError: beams: 0: the match's laser has 181 beams"), got[4]
    assert got[5].startswith("ValueError: laser_range: NaN"), got[5]
    assert got[6].startswith("ValueError: fov_deg: inf"), got[6]
    assert got[7] == "ValueError: rewards.tag: NaN must be finite", got[7]
    assert got[8] == "ValueError: rewards.tick: -inf must be finite", got[8]
    assert got[9].startswith("ValueError: max_steps:"), got[9]
    assert got[10] == "ValueError: ticks_per_step: 0 must be in 1..=100000", got[10]
    assert got[11].startswith("ValueError: robot_starts[0]:"), got[11]
    assert got[12] == "ValueError: rewards.tag: nan must be finite", got[12]
    assert got[13].startswith("ValueError: pixels_per_metre: nan"), got[13]
    assert got[14].startswith("ValueError: pixels_per_metre: 1000000.0 makes a frame"), got[14]
    assert got[15] == "accepted", got[15]


def test_the_engines_bounds_are_the_rules():
    # The engine's constants (lasertag_core::env::engine) and the server's declarations,
    # which write rules.json, cannot drift apart.
    bounds = SHIPPED["bounds"]
    assert _native.BOUNDS["robots"] == bounds["robots"]["maximum"]
    assert _native.BOUNDS["opponents"] == bounds["opponents"]["maximum"]
    assert _native.BOUNDS["detections"] == bounds["opponents"]["maximum"]
    assert _native.BOUNDS["time_limit_s"] == bounds["time_limit_s"]["maximum"]
    assert _native.BOUNDS["ticks_per_step"] == bounds["ticks"]["maximum"]
    assert _native.BOUNDS["agents"] >= 64 * bounds["robots"]["maximum"]


def test_unknown_agents_are_refused_by_id():
    env = lasertag_env.parallel_env(max_steps=20)
    env.reset(seed=1)
    with pytest.raises(ValueError, match=r"actions: no agent 'r7'; the agents are \['r0', 'r1'\]"):
        env.step({"r0": [0, 0, 0], "r7": [1, 0, 0]})
    with pytest.raises(ValueError, match="actions: no agent 0"):
        env.step({0: [1, 0, 0]})
    with pytest.raises(TypeError, match="actions must be a dict"):
        env.step([[1, 0, 0], [1, 0, 0]])
    env.step({"r0": [0, 0, 0]})  # a known agent left out still stands still
    # In a mixed team the planned robot is no agent: an action for it would be ignored.
    mixed = lasertag_env.parallel_env(robots=2, planner=["coordinated", "api"], max_steps=20)
    mixed.reset(seed=1)
    with pytest.raises(ValueError, match=r"no agent 'r0'; the agents are \['r1'\]"):
        mixed.step({"r0": [1, 0, 0], "r1": [1, 0, 0]})
    single = lasertag_env.single_agent_env(robot=1, others="hunter", max_steps=5)
    single.reset(seed=2)
    single.step(np.zeros(3, np.float32))  # the others' actions are by known ids


def test_actions_of_the_wrong_shape_are_refused():
    env = lasertag_env.parallel_env(max_steps=20)
    env.reset(seed=1)
    for bad in ([1.0, 0.5], [1, 0, 0, 1], [[1, 0, 0]], np.zeros((3, 1)), "100", 1.0):
        with pytest.raises(ValueError, match="action of r1"):
            env.step({"r0": [0, 0, 0], "r1": bad})
    v = lasertag_env.vector_env(2, max_steps=20)
    v.reset(seed=1)
    for shape in ((3, 3), (12,), (4, 3, 1), (3, 4)):
        with pytest.raises(ValueError, match=r"actions: shape"):
            v.step(np.zeros(shape, np.float32))
    with pytest.raises(TypeError):
        v.step(np.full((4, 3), "x"))
    # The raw engine takes exactly its shapes: the same values transposed would be read
    # as other robots' actions.
    e = v._engine
    obs = np.zeros((2, e.size), np.float32)
    rew = np.zeros(2)
    with pytest.raises(ValueError, match=r"actions: shape \[3, 2\], the engine needs \[2, 3\]"):
        e.step(0, np.zeros((3, 2), np.float32), obs, rew)
    with pytest.raises(ValueError, match=r"obs: shape"):
        e.step(0, np.zeros((2, 3), np.float32), np.zeros((1, 2 * e.size), np.float32), rew)
    with pytest.raises(IndexError, match="world 5: out of range 0..2"):
        e.step(5, np.zeros((2, 3), np.float32), obs, rew)
    with pytest.raises(ValueError, match=r"actions: shape \[2, 2, 2\], the engine needs"):
        e.time_parts(0, 3, np.zeros((2, 2, 2), np.float32))
    with pytest.raises(ValueError, match=r"actions: shape \[0, 2, 3\], the engine needs"):
        e.time_parts(0, 3, np.zeros((0, 2, 3), np.float32))


def test_the_http_backend_checks_the_same_before_its_first_request(server):
    for kwargs, message in (
        (dict(detections=10**9), r"detections: 1000000000 must be in 0..=32"),
        (dict(time_limit_s=math.nan), r"time_limit_s: nan must be finite"),
        (dict(rewards={"tick": math.inf}), r"rewards.tick: inf must be finite"),
        (dict(pixels_per_metre=0), r"pixels_per_metre: 0 must be finite and above 0"),
    ):
        with pytest.raises(ValueError, match=message):
            lasertag_env.parallel_env(server=server, **kwargs)
    env = lasertag_env.parallel_env(server=server, max_steps=5)
    try:
        env.reset(seed=1)
        with pytest.raises(ValueError, match="actions: no agent 'r2'"):
            env.step({"r2": [1, 0, 0]})
    finally:
        env.close()


def test_a_map_object_is_bounded_by_the_map_rules():
    office = lasertag_env.shipped_map("office")
    for field, value in (("width", math.nan), ("height", math.inf), ("width", 1e9)):
        bad = json.loads(json.dumps(office))
        bad[field] = value
        with pytest.raises(ValueError, match=f"map.{field}"):
            lasertag_env.parallel_env(map=bad)


def test_max_steps_and_timing_runs_are_bounded_as_the_server_bounds_them():
    most = lasertag_env.rules.most_steps(SHIPPED)
    assert most == 86400 * 20 == _native.BOUNDS["max_steps"]
    got = outcomes(
        f"lasertag_env.parallel_env(max_steps={most + 1})",
        f"lasertag_env.vector_env(2, max_steps={most + 1})",
        f"engine(max_steps={most + 1})",
        f"engine(max_steps={most}).time_parts(0, {_native.BOUNDS['timed_ticks'] + 1}, np.zeros((1, 2, 3), np.float32))",
        "engine(ticks=1000).time_parts(0, 101, np.zeros((1, 2, 3), np.float32))",
        "engine().time_parts(0, 0, np.zeros((1, 2, 3), np.float32))",
        # Within the bounds still works.
        f"lasertag_env.parallel_env(max_steps={most}).reset()",
        "engine(ticks=1000).time_parts(0, 100, np.zeros((1, 2, 3), np.float32))",
    )
    bound = f"must be in 1..={most} (a step is at least a tick, and a match lasts at most that many)"
    assert got[0] == f"ValueError: max_steps: {most + 1} {bound}, or None", got[0]
    assert got[1] == got[0]
    assert got[2] == got[0]
    assert got[3].startswith("ValueError: steps: 100001 must be in 1..=100000"), got[3]
    assert got[4].startswith("ValueError: steps: 101 must be in 1..=100 (at most 100000 ticks"), got[4]
    assert got[5].startswith("ValueError: steps: 0 must be in 1..=100000"), got[5]
    assert got[6] == "accepted", got[6]
    assert got[7] == "accepted", got[7]


def test_the_http_backend_bounds_max_steps_as_the_native_one(server):
    most = lasertag_env.rules.most_steps(SHIPPED)
    with pytest.raises(ValueError, match=rf"max_steps: {most + 1} must be in 1..={most}"):
        lasertag_env.parallel_env(server=server, max_steps=most + 1)


# A closet with room for two agents 1 m apart only near its ends: random starts that put the
# first agent in its middle leave the second nowhere.
CLOSET = {
    "name": "closet", "width": 2.0, "height": 1.0, "obstacles": [],
    "robot_spawns": [[0.5, 0.5, 0.0]], "opponent_spawns": [[1.5, 0.5]], "landmarks": [],
}


def test_an_auto_reset_that_places_no_match_raises_naming_the_world_and_seed():
    # One world, an episode a step: some seed's random starts leave no room.
    for seed in range(200):
        try:
            v = lasertag_env.vector_env(1, map=CLOSET, robots=1, opponents=1, seed=seed,
                                        placement="random", max_steps=1)
            v.reset(seed=seed)
            break
        except ValueError:
            continue
    else:
        pytest.fail("no seed places the first episode")
    error = None
    for _ in range(400):
        try:
            v.step(np.zeros((1, 3), np.float32))
        except RuntimeError as e:
            error = str(e)
            break
    assert error is not None, "every seed placed its match"
    assert error.startswith("world 0: its next episode (seed "), error
    assert "could not start" in error and 'placement "spawns"' in error, error
    # The world is not left replaying its ended episode: a later step draws the next seed.
    for _ in range(400):
        try:
            v.step(np.zeros((1, 3), np.float32))
            break
        except RuntimeError:
            continue
    else:
        pytest.fail("no later seed places the match")
