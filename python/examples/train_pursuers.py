"""Learns a pursuer policy against the built-in bots with Augmented Random Search (Mania,
Guy and Recht, 2018: a linear policy, antithetic random perturbations, the best directions'
reward differences, observations normalised by running statistics), in numpy, on the
in-process vector environment; then compares its capture times with the paper's planners.

Every robot of the team runs the same linear policy on a compact view of its own
observation: the laser's 181 beams as the nearest range in 18 sectors of 10°, then the
rest of the vector (pose estimate, spread, tag readiness, time, the nearest detection,
the teammate). Actions are forward, turn and tag (fires above 0.5), clipped.

Each generation evaluates ``2 × directions`` perturbed policies on the same ``seeds_per``
match seeds (common random numbers), every episode in one vector of worlds stepped in one
call; the fitness is the episode's return (1 a tag, -0.001 a tick) plus 0.002 a step in
which some robot sees an opponent (a shaping term: without it the first captures are too
rare to follow). It writes:

- ``learning_curve.png``: the mean return of the unperturbed policy on held-out seeds, and
  its capture rate, against the environment steps spent;
- ``capture_times.csv`` and a table on stdout: capture times on the fixed evaluation seeds
  for the learned policy, the ``baseline`` planner and the ``coordinated`` planner, the
  same matches (map, bots, seeds) for all three;
- ``policy.npz``: the weights and the observation statistics.

About 6 minutes on 2 cores with the defaults::

    pip install ./python matplotlib
    python python/examples/train_pursuers.py --out results/train

docs/research.md ("A policy that learns") shows the figures of one run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import lasertag_env  # noqa: E402

SECTORS = 18
#: What every environment of the example shares: 2 robots hunting 1 wandering bot in the
#: office, a decision every 4 ticks (5 a second), episodes of at most 90 s.
ENV = dict(map="office", robots=2, opponents=1, opponent_bot="wander", ticks_per_step=4,
           max_steps=450)


def features(obs: np.ndarray, beams: int) -> np.ndarray:
    """(n, size) observation vectors to (n, features): sector minima of the scan, the
    rest as it is, and a constant 1."""
    n = obs.shape[0]
    scan = obs[:, : beams - 1].reshape(n, SECTORS, -1).min(axis=2)
    return np.concatenate([scan, obs[:, beams:], np.ones((n, 1), np.float32)], axis=1)


class Running:
    """Running mean and variance of the features (ARS's V2 normalisation)."""

    def __init__(self, dim: int):
        self.n = 0
        self.mean = np.zeros(dim)
        self.m2 = np.zeros(dim)

    def update(self, x: np.ndarray) -> None:
        # Chan et al.'s pairwise combination of two samples' means and squared deviations.
        k = x.shape[0]
        if k == 0:
            return
        delta = x.mean(axis=0) - self.mean
        total = self.n + k
        self.mean += delta * k / total
        self.m2 += x.var(axis=0) * k + delta**2 * self.n * k / total
        self.n = total

    def std(self) -> np.ndarray:
        s = np.sqrt(self.m2 / max(self.n, 1))
        s[s < 1e-3] = 1.0  # constant features (the bias) are left as they are
        return s


def rollout(env, weights: np.ndarray, seeds: list[int], stats: Running | None,
            mean: np.ndarray, std: np.ndarray, beams: int) -> dict:
    """One episode per world, world ``w`` with policy ``weights[w]`` (3 × features) and
    seed ``seeds[w]``. Returns per world: the return (with the shaping term), whether the
    robots captured, the capture time (s), and the steps taken; the features seen update
    ``stats``."""
    worlds, robots = env.num_worlds, env.robots
    obs, _ = env.reset(seed=seeds)
    ret = np.zeros(worlds)
    done = np.zeros(worlds, bool)
    captured = np.zeros(worlds, bool)
    steps = np.zeros(worlds, int)
    per_step_s = ENV["ticks_per_step"] / 20.0
    while not done.all():
        f = features(obs, beams)
        if stats is not None:
            stats.update(f[np.repeat(~done, robots)])
        z = ((f - mean) / std).reshape(worlds, robots, -1)
        act = np.einsum("wak,wrk->wra", weights, z).reshape(worlds * robots, 3)
        np.clip(act, -1.0, 1.0, out=act)
        obs, rew, term, trunc, _ = env.step(act.astype(np.float32))
        live = ~done
        seen = obs[:, beams + 8].reshape(worlds, robots).max(axis=1) > 0
        ret[live] += rew.reshape(worlds, robots).sum(axis=1)[live] + 0.002 * seen[live]
        steps[live] += 1
        t, tr = term.reshape(worlds, robots)[:, 0], trunc.reshape(worlds, robots)[:, 0]
        captured |= live & t
        done |= t | tr
    return {"return": ret, "captured": captured, "time": steps * per_step_s, "steps": steps}


def planner_times(planner: str, seeds: list[int]) -> np.ndarray:
    """Capture times (s; inf when not captured) of a built-in planner on ``seeds``."""
    env = lasertag_env.vector_env(len(seeds), planner=planner, **ENV)
    obs, _ = env.reset(seed=seeds)
    worlds = env.num_worlds
    done = np.zeros(worlds, bool)
    out = np.full(worlds, np.inf)
    zero = np.zeros((env.num_envs, 3), np.float32)
    k = 0
    while not done.all():
        _, _, term, trunc, _ = env.step(zero)
        k += 1
        t, tr = term.reshape(worlds, -1)[:, 0], trunc.reshape(worlds, -1)[:, 0]
        out[~done & t] = k * ENV["ticks_per_step"] / 20.0
        done |= t | tr
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--generations", type=int, default=40)
    p.add_argument("--directions", type=int, default=12)
    p.add_argument("--top", type=int, default=6, help="best directions used per update")
    p.add_argument("--seeds-per", type=int, default=2, help="match seeds per policy a generation")
    p.add_argument("--step-size", type=float, default=0.05)
    p.add_argument("--noise", type=float, default=0.3)
    p.add_argument("--eval-seeds", type=int, default=100, help="fixed seeds of the final comparison")
    p.add_argument("--eval-every", type=int, default=4)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="results/train_pursuers")
    args = p.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = np.random.default_rng(args.seed)

    layout = lasertag_env.parallel_env(**ENV).layout
    beams = layout.beams
    dim = SECTORS + layout.size - beams + 1
    theta = np.zeros((3, dim))
    stats = Running(dim)
    pairs, k = args.directions, args.seeds_per
    train = lasertag_env.vector_env(2 * pairs * k, **ENV)
    held_out = [10_000 + i for i in range(16)]
    probe = lasertag_env.vector_env(len(held_out), **ENV)
    curve = []  # (env steps so far, mean return, capture rate)
    env_steps = 0
    t0 = time.perf_counter()

    def evaluate(gen: int) -> None:
        r = rollout(probe, np.repeat(theta[None], len(held_out), axis=0), held_out, None,
                    stats.mean, stats.std(), beams)
        curve.append((env_steps, r["return"].mean(), r["captured"].mean()))
        print(f"generation {gen:3d}  {env_steps:9,d} steps  {time.perf_counter() - t0:6.0f} s"
              f"  held-out return {r['return'].mean():6.3f}  captured {r['captured'].mean():4.0%}",
              flush=True)

    evaluate(0)
    for gen in range(1, args.generations + 1):
        seeds = [int(s) for s in rng.integers(0, 2**31, size=k)]
        deltas = rng.standard_normal((pairs, 3, dim))
        # Worlds: (direction, sign, seed), each direction's two signs on the same seeds.
        signs = np.array([1.0, -1.0])
        weights = theta[None, None, None] + args.noise * (
            signs[None, :, None, None, None] * deltas[:, None, None]
        )
        weights = np.broadcast_to(weights, (pairs, 2, k, 3, dim)).reshape(-1, 3, dim)
        mean, std = stats.mean.copy(), stats.std()
        r = rollout(train, weights, seeds * (2 * pairs), stats, mean, std, beams)
        env_steps += int(r["steps"].sum())
        ret = r["return"].reshape(pairs, 2, k).mean(axis=2)
        best = np.argsort(-ret.max(axis=1))[: args.top]
        sigma = ret[best].std() or 1.0
        step = ((ret[best, 0] - ret[best, 1])[:, None, None] * deltas[best]).sum(axis=0)
        theta += args.step_size / (args.top * sigma) * step
        if gen % args.eval_every == 0 or gen == args.generations:
            evaluate(gen)
    np.savez(os.path.join(args.out, "policy.npz"), theta=theta, mean=stats.mean,
             std=stats.std())

    # The learning curve.
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps_axis = [c[0] for c in curve]
    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=120)
    ax.plot(steps_axis, [c[1] for c in curve], marker="o", label="mean return (held-out seeds)")
    ax.set_xlabel("environment steps (one world, every robot acting, 4 ticks)")
    ax.set_ylabel("return")
    ax2 = ax.twinx()
    ax2.plot(steps_axis, [100 * c[2] for c in curve], color="tab:orange", marker=".",
             label="captured within 90 s (%)")
    ax2.set_ylabel("captured (%)")
    ax2.set_ylim(0, 100)
    ax.legend(*[sum(x, []) for x in zip(ax.get_legend_handles_labels(), ax2.get_legend_handles_labels())],
              loc="center right", fontsize=8)
    ax.set_title("ARS, linear policy: 2 robots v 1 wander bot, office")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "learning_curve.png"))

    # Capture times on fixed seeds: the learned policy and the paper's planners.
    eval_seeds = [20_000 + i for i in range(args.eval_seeds)]
    final = lasertag_env.vector_env(len(eval_seeds), **ENV)
    r = rollout(final, np.repeat(theta[None], len(eval_seeds), axis=0), eval_seeds, None,
                stats.mean, stats.std(), beams)
    learned = np.where(r["captured"], r["time"], np.inf)
    times = {"learned (ARS)": learned,
             "baseline": planner_times("baseline", eval_seeds),
             "coordinated": planner_times("coordinated", eval_seeds)}
    with open(os.path.join(args.out, "capture_times.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["seed", *times])
        for i, s in enumerate(eval_seeds):
            w.writerow([s, *(f"{times[n][i]:.1f}" if np.isfinite(times[n][i]) else "" for n in times)])
    print(f"\ncapture times on {len(eval_seeds)} fixed seeds (90 s limit), "
          f"{time.perf_counter() - t0:.0f} s in all:")
    print(f"{'policy':16} {'captured':>9} {'median (s)':>11} {'mean of captured (s)':>21}")
    for name, t in times.items():
        ok = np.isfinite(t)
        med = np.median(t)  # inf when half or more were not captured
        med_s = f"{med:.1f}" if np.isfinite(med) else "> 90"
        mean_s = f"{t[ok].mean():.1f}" if ok.any() else "-"
        print(f"{name:16} {ok.mean():9.0%} {med_s:>11} {mean_s:>21}")


if __name__ == "__main__":
    main()
