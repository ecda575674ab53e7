"""Steps per second of every way to run lasertag from Python, and PettingZoo's MPE
``simple_tag``, in one run, on one machine; and where one in-process step's time goes.

Rows (each steps random actions for ``--seconds`` after ``--warmup``, in this process):

- ``simple_tag``: MPE's predator-prey, a pure Python/numpy environment (``mpe2``), its
  PettingZoo parallel API;
- ``http``: :func:`lasertag_env.parallel_env` on a local server (the release binary);
- ``native``: the same, in-process (the default backend);
- ``vector N``: :func:`lasertag_env.vector_env` with N worlds, one call a step for all;
- ``vector N, team_tracker=False``: the same with the team tracker at its minimum;
- ``vector N, light``: the same with the lightest settings (see ``LIGHT``).

A "step" is one step of one world (every robot acting once), so the rows compare; the
vector rows also give robot-steps (entries of the vector). Then, for one in-process world,
a step's time in parts: the ticks (the core's match, with the rewards), the observation
vectors, and the rest (Python: the environment's dictionaries, numpy copies, the call).

numpy's OpenBLAS threads spin after any BLAS call and compete for the cores, so this sets
``OPENBLAS_NUM_THREADS=1`` before importing numpy. Example::

    cargo build --release && pip install './python[bench]'
    python python/benchmarks/backends.py --seconds 5
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import lasertag_env  # noqa: E402

#: The team tracker at its minimum (10 particles a role): the observation's belief parts
#: are coarser, the step cheaper.
PLAIN = {"team_tracker": False}
#: The light rows: the tracker at its minimum and no self-localisation (each robot's
#: estimate is its odometry, dead reckoning that drifts; the observation keeps its shape).
LIGHT = {**PLAIN, "match_settings": {"localisation": False}}


def timed(step, reset, warmup: float, seconds: float) -> tuple[int, float]:
    """Steps ``step()`` (which says whether the episode ended) for ``seconds`` of wall time
    after ``warmup``; (steps, seconds)."""
    t_warm = time.perf_counter() + warmup
    while time.perf_counter() < t_warm:
        if step():
            reset()
    n = 0
    t0 = time.perf_counter()
    t_end = t0 + seconds
    while True:
        if step():
            reset()
        n += 1
        if (n & 15) == 0 and time.perf_counter() >= t_end:
            return n, time.perf_counter() - t0


def simple_tag(args) -> float:
    try:
        from mpe2 import simple_tag_v3
    except ImportError:  # PettingZoo before 1.25 shipped MPE itself
        from pettingzoo.mpe import simple_tag_v3
    env = simple_tag_v3.parallel_env(max_cycles=1200)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = [{a: int(rng.integers(5)) for a in env.possible_agents} for _ in range(4096)]
    k = [0]

    def step():
        env.step(actions[k[0] & 4095])
        k[0] += 1
        return not env.agents

    n, dt = timed(step, lambda: env.reset(), args.warmup, args.seconds)
    return n / dt


def parallel(args, **kwargs) -> float:
    env = lasertag_env.parallel_env(max_steps=1200, **kwargs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    table = rng.uniform(-1, 1, size=(4096, len(env.possible_agents), 3)).astype(np.float32)
    k = [0]

    def step():
        a = table[k[0] & 4095]
        k[0] += 1
        *_, term, trunc, _ = env.step({agent: a[i] for i, agent in enumerate(env.possible_agents)})
        return not env.agents

    try:
        n, dt = timed(step, lambda: env.reset(), args.warmup, args.seconds)
    finally:
        env.close()
    return n / dt


def vector(args, worlds: int, **kwargs) -> float:
    env = lasertag_env.vector_env(worlds, max_steps=1200, copy=False, **kwargs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    table = rng.uniform(-1, 1, size=(64, env.num_envs, 3)).astype(np.float32)
    k = [0]

    def step():
        env.step(table[k[0] & 63])
        k[0] += 1
        return False  # the vector resets its worlds itself

    n, dt = timed(step, lambda: None, args.warmup, args.seconds)
    return n * worlds / dt


def parts(args) -> dict:
    """One in-process world's step in parts, in µs."""
    env = lasertag_env.parallel_env(max_steps=1200)
    env.reset(seed=0)
    n = 8000
    # The same random actions as the whole steps' (a robot that moves more localises more).
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(4096, len(env.possible_agents), 3)).astype(np.float32)
    ticks_s, vectors_s = env._engine.time_parts(0, n, actions)
    return {"ticks": 1e6 * ticks_s / n, "vectors": 1e6 * vectors_s / n,
            "whole_rate": parallel(args) if args.parts_only else None}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=5.0)
    p.add_argument("--warmup", type=float, default=1.0)
    p.add_argument("--worlds", type=int, nargs="+", default=[1, 2, 8, 64])
    p.add_argument("--no-http", action="store_true", help="skip the HTTP row (no server binary)")
    p.add_argument("--no-simple-tag", action="store_true", help="skip MPE's simple_tag")
    p.add_argument("--parts-only", action="store_true", help="only the step's parts")
    args = p.parse_args()

    rows: list[tuple[str, float, float | None]] = []
    native_rate = None
    if not args.parts_only:
        if not args.no_simple_tag:
            rows.append(("simple_tag (MPE, 1 env)", simple_tag(args), None))
        if not args.no_http:
            with lasertag_env.LocalServer() as server:
                rows.append(("http (1 env, local server)", parallel(args, server=server), None))
        native_rate = parallel(args)
        rows.append(("native (1 env)", native_rate, None))
        for w in args.worlds:
            rate = vector(args, w)
            rows.append((f"vector {w}", rate, rate * 2))
        w = max(args.worlds)
        rate = vector(args, w, **PLAIN)
        rows.append((f"vector {w}, team_tracker=False", rate, rate * 2))
        rate = vector(args, w, **LIGHT)
        rows.append((f"vector {w}, light", rate, rate * 2))
        print(f"{'configuration':32} {'world steps/s':>14} {'robot steps/s':>14}")
        for name, rate, robot_rate in rows:
            extra = f"{robot_rate:14,.0f}" if robot_rate else f"{'':14}"
            print(f"{name:32} {rate:14,.0f} {extra}")
    part = parts(args)
    rate = native_rate or part["whole_rate"]
    step_us = 1e6 / rate
    print()
    print("one in-process step (2 robots, 1 wander bot, office), µs:")
    print(f"  ticks and rewards  {part['ticks']:7.1f}")
    print(f"  observation vectors{part['vectors']:7.1f}")
    print(f"  Python and the call{step_us - part['ticks'] - part['vectors']:7.1f}")
    print(f"  whole step         {step_us:7.1f}  ({rate:,.0f} steps/s)")


if __name__ == "__main__":
    main()
