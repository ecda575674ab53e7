"""Trains the robot team with PPO on the in-process vector environment, from each robot's
whole observation (its scan, pose, sightings, teammate and the team belief), then compares
its capture times with the paper's planners on held-out seeds and a held-out map, and
exports the policy to ONNX for the server to run.

Why this shape: one readable file on plain PyTorch (CPU), with no RL framework to pin or
follow across versions. The algorithm is CleanRL's single-file continuous-action PPO
(``ppo_continuous_action.py``: Huang et al., 2022; Schulman et al., 2017): separate actor
and critic MLPs of two tanh layers (orthogonal initialisation), a state-independent
log-std, GAE(λ), the clipped surrogate, clipped value loss, advantage normalisation per
minibatch, gradient clipping and a linearly annealed learning rate. Adapted to a team:

- **One policy shared by the robots.** Entry ``w * robots + r`` of a vector environment is
  robot ``r`` of world ``w``; every robot is its own sample (its own observation, action,
  reward, value and GAE chain), and all of them train the one actor and one critic.
- **Several maps.** Vector environments per training map, stepped one after the other
  every step; a rollout holds the same number of worlds of each map, and of those
  ``--random-starts`` (half) start every episode from random free positions (placement
  ``random``) rather than the map's spawns, so that the policy meets more situations than
  a few spawn pairs. One map is held out of training entirely and only evaluated (from its
  spawns, as every evaluation).
- **Auto-reset on the next step.** The step after an episode's end ignores the actions and
  returns the next episode's first observation: that sample is left out of the loss, and
  the episode's last observation (which that step's sample holds) bootstraps the value of a
  truncated episode; a capture (termination) has value 0 after it.
- **No normalisation.** Every observation value is already in [-1, 1] and the exported model
  takes the raw vector, so there is no running mean or scale, of observations or of rewards.
  Observation parts named by ``--mask`` are zeroed before the first layer (the export
  folds that into the first layer's weights, so the model still reads the whole vector).
  By default ``time`` (in training it counts the steps of a 90 s episode, in a served
  match the match's time over a longer limit), ``pose`` and ``teammates`` (positions and
  headings in the map's frame, scaled by its size: what they mean changes from map to
  map). What is left is egocentric: the scan, the sightings, the estimate's spread, the
  tag device, and the belief grid and roles, which the core computes relative to the
  robot. Pilots of 400,000 steps (one seed each, 20 held-out seeds on the held-out map):
  masking ``time`` only, 90% captured (median 51.6 s); random starts too, 75% (62.2 s);
  the default mask without random starts, 60% (65.7 s); both, as the defaults, 100%
  (12.1 s).

``--bc-steps N`` first fits the actor's mean to the coordinated planner's decisions on the
same observations (behaviour cloning from ``vector_env.teacher_actions``: N environment steps
of the planner on the training maps, ``--bc-epochs`` passes of squared error), so that PPO
starts from the paper's planner rather than from nothing. Off by default: the shipped
policy was trained without it.

The action is forward, turn and tag (fires above 0.5): a Gaussian around the actor's
output in training, the output itself (the mean) in every evaluation, as the server runs it.
The environment clips forward and turn to [-1, 1].

Matches: 2 robots against 1 bot, a decision every 4 ticks (5 a second; ``--ticks-per-step``
sets it), 90 s at most; ``--bots`` (``wander`` and ``evade``: the one that strolls and the
one that runs from the robots) share each map's worlds equally, and every evaluation plays
each. Reward per robot and step: the environment's (1 for the robot whose shot tags,
``--team-tag`` to each robot for any robot's tag, -0.001 a tick) plus the shaping
``--see-bonus`` a step in which the robot sees an opponent (less than the 0.004 a step of 4
ticks costs, so watching never pays more than capturing; deciding every 2 ticks, pass less
than 0.002).

Outputs in ``--out``:

- ``curve.csv`` and ``learning_curve.png``: the deterministic policy's mean return (the
  environment's reward, no shaping, summed over robots), capture rate and median capture
  time on fixed seeds of the held-out map and of the training maps, per bot, against the
  environment steps spent;
- ``capture_times.csv``: per map, bot and seed, the learned policy's, the ``baseline`` and the
  ``coordinated`` planners' capture times (empty: not captured in 90 s) on the same matches;
- ``policy.pt`` (the actor, critic and settings) and ``policy.onnx`` (the actor's mean only:
  Gemm and Tanh, input ``obs`` [1, 240], output ``action`` [1, 3]; checked with
  ``onnx.checker``, its operators against the server's allow-list, and its outputs against
  torch's);
- the loop's speed on stdout with each evaluation, and in ``summary.json``: environment steps
  a second of collecting, and of collecting and learning together (evaluations apart);
- a table on stdout: per map and bot, captures and median capture times, the ratios learned /
  baseline and learned / coordinated, and Wilcoxon signed-rank tests on the per-seed times
  (a capture not made counts as the 90 s limit).

::

    pip install ./python torch onnx matplotlib
    python python/examples/train_team.py --out results/train_team          # about 55 min on 2 cores
    python python/examples/train_team.py --smoke --out /tmp/smoke          # under a minute

docs/research.md ("A team that learns from the belief") shows the figures of one run.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import concurrent.futures  # noqa: E402
import csv  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
import warnings  # noqa: E402
from torch import nn  # noqa: E402

import lasertag_env  # noqa: E402

#: What every environment shares: 2 robots hunting 1 bot, a decision every 4 ticks (5 a
#: second; ``--ticks-per-step`` changes it), episodes of at most 90 s (450 steps).
ENV = dict(robots=2, opponents=1, ticks_per_step=4, max_steps=450)
STEP_S = ENV["ticks_per_step"] / 20.0
LIMIT_S = ENV["max_steps"] * STEP_S


def decide_every(ticks: int) -> None:
    """Sets the decision rate of every environment the script makes, episodes still 90 s."""
    global STEP_S
    if ticks < 1 or 1800 % ticks:
        raise SystemExit(f"--ticks-per-step {ticks}: must divide a 90 s episode's 1,800 ticks")
    ENV.update(ticks_per_step=ticks, max_steps=int(LIMIT_S * 20) // ticks)
    STEP_S = ticks / 20.0


#: Operators the server's policy runtime accepts (policy/lib.rs).
ALLOWED_OPS = {"Gemm", "MatMul", "Add", "Relu", "Tanh", "Sigmoid", "Identity", "Flatten"}
#: Seeds: the learning curve's (each map), the final comparison's (each map, 20000 + i),
#: and the first training episodes' (seed * 1,000,000 + 100,000 (map index + 1) + world).
CURVE_SEED, EVAL_SEED = 10_000, 20_000


def layer(linear: nn.Linear, std: float = math.sqrt(2), bias: float = 0.0) -> nn.Linear:
    nn.init.orthogonal_(linear.weight, std)
    nn.init.constant_(linear.bias, bias)
    return linear


class Agent(nn.Module):
    """CleanRL's continuous-action actor-critic: two tanh MLPs and a log-std."""

    def __init__(self, obs_dim: int, hidden: int, mask: np.ndarray, log_std: float):
        super().__init__()
        self.register_buffer("mask", torch.as_tensor(mask, dtype=torch.float32))
        self.critic = nn.Sequential(
            layer(nn.Linear(obs_dim, hidden)), nn.Tanh(),
            layer(nn.Linear(hidden, hidden)), nn.Tanh(),
            layer(nn.Linear(hidden, 1), std=1.0),
        )
        self.actor = nn.Sequential(
            layer(nn.Linear(obs_dim, hidden)), nn.Tanh(),
            layer(nn.Linear(hidden, hidden)), nn.Tanh(),
            layer(nn.Linear(hidden, 3), std=0.01),
        )
        self.log_std = nn.Parameter(torch.full((3,), float(log_std)))

    def value(self, x: torch.Tensor) -> torch.Tensor:
        return self.critic(x * self.mask).squeeze(-1)

    def mean(self, x: torch.Tensor) -> torch.Tensor:
        return self.actor(x * self.mask)

    def act(self, x: torch.Tensor, action: torch.Tensor | None = None):
        mean = self.mean(x)
        dist = torch.distributions.Normal(mean, self.log_std.exp().expand_as(mean))
        if action is None:
            action = dist.sample()
        return action, dist.log_prob(action).sum(-1), dist.entropy().sum(-1), self.value(x)

    def exported(self) -> nn.Sequential:
        """The actor's mean as a plain chain (the mask folded into the first layer)."""
        seq = nn.Sequential(*[m for m in self.actor])
        import copy

        seq = copy.deepcopy(seq)
        with torch.no_grad():
            seq[0].weight.mul_(self.mask[None, :])
        return seq.eval()


# ---------------------------------------------------------------------------------------
# Evaluation: the deterministic policy (the mean) or a built-in planner on fixed seeds.


def play(map_name: str, seeds: list[int], bot: str, actor=None, planner: str = "api") -> dict:
    """One episode per seed on ``map_name``, driven by ``actor`` (observations → actions,
    numpy) or by the built-in ``planner``. Per seed: the capture time (s; inf when not
    captured) and the return (the environment's reward summed over the robots)."""
    env = lasertag_env.vector_env(len(seeds), map=map_name, opponent_bot=bot, planner=planner,
                                  **ENV)
    obs, _ = env.reset(seed=seeds)
    worlds, robots = env.num_worlds, env.robots
    done = np.zeros(worlds, bool)
    times = np.full(worlds, np.inf)
    ret = np.zeros(worlds)
    act = np.zeros((env.num_envs, 3), np.float32)
    k = 0
    while not done.all():
        if actor is not None:
            act = actor(obs)
        obs, rew, term, trunc, _ = env.step(act)
        k += 1
        live = ~done
        ret[live] += rew.reshape(worlds, robots).sum(axis=1)[live]
        t, tr = term.reshape(worlds, robots)[:, 0], trunc.reshape(worlds, robots)[:, 0]
        times[live & t] = k * STEP_S
        done |= t | tr
    return {"time": times, "return": ret}


def speeds(env_steps: int, collect_s: float, learn_s: float) -> dict:
    """The training loop's speed so far: environment steps (one world's, every robot acting)
    a second of collecting, and of collecting and learning together (evaluations apart)."""
    return {"collect": round(env_steps / max(collect_s, 1e-9)),
            "end_to_end": round(env_steps / max(collect_s + learn_s, 1e-9))}


def speed_line(env_steps: int, collect_s: float, learn_s: float) -> str:
    """:func:`speeds` as a line of the log."""
    s = speeds(env_steps, collect_s, learn_s)
    return (f"{s['collect']:,} steps/s collecting, {s['end_to_end']:,} steps/s end to end "
            f"(collect {collect_s:.0f} s, learn {learn_s:.0f} s)")


def mean_actor(model: nn.Module):
    def run(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return model(torch.from_numpy(obs)).numpy().astype(np.float32)
    return run


# ---------------------------------------------------------------------------------------
# Statistics.


def wilcoxon(x: np.ndarray, y: np.ndarray) -> tuple[float, int]:
    """Two-sided Wilcoxon signed-rank test of x - y (zero differences dropped, ties given
    mid-ranks): the exact null distribution of W+ for up to 50 pairs (by counting subsets
    of the ranks, in half-ranks), the normal approximation with tie correction above.
    Returns (p, pairs used)."""
    d = np.asarray(x, float) - np.asarray(y, float)
    d = d[d != 0]
    n = len(d)
    if n == 0:
        return 1.0, 0
    a = np.abs(d)
    order = np.argsort(a, kind="stable")
    ranks = np.empty(n)
    sa = a[order]
    i = 0
    while i < n:
        j = i
        while j + 1 < n and sa[j + 1] == sa[i]:
            j += 1
        ranks[order[i : j + 1]] = (i + j) / 2 + 1
        i = j + 1
    w_plus = ranks[d > 0].sum()
    if n <= 50:
        # Counts of subsets of the (half-)ranks by their sum: the exact null distribution.
        h = np.rint(2 * ranks).astype(int)
        total = int(h.sum())
        counts = np.zeros(total + 1)
        counts[0] = 1.0
        for r in h:
            counts[r:] = counts[r:] + counts[: total + 1 - r].copy()
        probs = counts / counts.sum()
        k = int(round(2 * w_plus))
        lo, hi = probs[: k + 1].sum(), probs[k:].sum()
        return float(min(1.0, 2 * min(lo, hi))), n
    _, tie_counts = np.unique(a, return_counts=True)
    var = n * (n + 1) * (2 * n + 1) / 24 - (tie_counts**3 - tie_counts).sum() / 48
    z = (w_plus - n * (n + 1) / 4) / math.sqrt(var)
    return float(math.erfc(abs(z) / math.sqrt(2))), n


# ---------------------------------------------------------------------------------------
# ONNX export and checks.


def gemm_chain(model) -> callable:
    """A numpy evaluator of an ONNX graph of Gemm / MatMul + Add / Relu / Tanh / Sigmoid /
    Identity / Flatten, each node on the previous one's output (what the server runs)."""
    from onnx import numpy_helper

    g = model.graph
    consts = {t.name: numpy_helper.to_array(t).astype(np.float32) for t in g.initializer}

    def run(x: np.ndarray) -> np.ndarray:
        v = np.asarray(x, np.float32)
        for node in g.node:
            attrs = {a.name: a for a in node.attribute}
            params = [consts[i] for i in node.input[1:]]
            if node.op_type == "Gemm":
                w = params[0].T if attrs.get("transB") and attrs["transB"].i else params[0]
                v = v @ w + (params[1] if len(params) > 1 else 0)
            elif node.op_type == "MatMul":
                v = v @ params[0]
            elif node.op_type == "Add":
                v = v + params[0]
            elif node.op_type == "Tanh":
                v = np.tanh(v)
            elif node.op_type == "Relu":
                v = np.maximum(v, 0)
            elif node.op_type == "Sigmoid":
                v = 1 / (1 + np.exp(-v))
            elif node.op_type in ("Identity", "Flatten"):
                pass
            else:
                raise ValueError(f"operator {node.op_type} outside the allow-list")
        return v

    return run


def export_onnx(seq: nn.Sequential, obs_dim: int, path: str, probe: np.ndarray) -> dict:
    import onnx

    warnings.filterwarnings("ignore", message=".*legacy TorchScript-based ONNX export")
    torch.onnx.export(seq, torch.zeros(1, obs_dim), path, input_names=["obs"],
                      output_names=["action"], opset_version=17, do_constant_folding=True,
                      dynamo=False)
    model = onnx.load(path)
    onnx.checker.check_model(model, full_check=True)
    ops = [n.op_type for n in model.graph.node]
    bad = sorted(set(ops) - ALLOWED_OPS)
    assert not bad, f"operators outside the server's allow-list: {bad}"
    assert len(model.graph.input) == 1 and len(model.graph.output) == 1
    dims = [d.dim_value for d in model.graph.input[0].type.tensor_type.shape.dim]
    out_dims = [d.dim_value for d in model.graph.output[0].type.tensor_type.shape.dim]
    assert dims == [1, obs_dim] and out_dims == [1, 3], (dims, out_dims)
    assert model.graph.input[0].type.tensor_type.elem_type == onnx.TensorProto.FLOAT
    # Each node takes the previous one's output: a single chain from the input to the output.
    current = model.graph.input[0].name
    for node in model.graph.node:
        data = [i for i in node.input if i not in {t.name for t in model.graph.initializer}]
        assert data == [current], f"{node.op_type} is not on the chain"
        current = node.output[0]
    assert current == model.graph.output[0].name
    run = gemm_chain(model)
    rng = np.random.default_rng(0)
    xs = np.concatenate([probe, rng.uniform(-1, 1, (64, obs_dim)).astype(np.float32)])
    with torch.no_grad():
        ref = seq(torch.from_numpy(xs)).numpy()
    got = np.concatenate([run(x[None]) for x in xs])
    err = float(np.abs(got - ref).max())
    assert err < 1e-4, f"ONNX and torch disagree by {err}"
    return {"ops": ops, "input": dims, "output": out_dims, "max_abs_diff": err,
            "bytes": os.path.getsize(path)}


# ---------------------------------------------------------------------------------------


def map_envs(maps: list[str], bots: list[str], worlds_per_map: int, random_starts: float,
             seed: int, **kwargs) -> list:
    """Per map and bot (the map's worlds shared equally between the bots), a vector of
    worlds starting from the map's spawns and, for the ``random_starts`` share, one starting
    from random free positions (placement "random"). The first worlds' seeds: ``seed`` +
    100,000 (map index + 1) + 20,000 bot index + 10,000 for the random starts."""
    per_bot = max(1, worlds_per_map // len(bots))
    n_random = int(round(random_starts * per_bot))
    envs = []
    for i, m in enumerate(maps):
        for j, b in enumerate(bots):
            for k, (n, placement) in enumerate([(per_bot - n_random, None), (n_random, "random")]):
                if n > 0:
                    envs.append(lasertag_env.vector_env(
                        n, map=m, opponent_bot=b, placement=placement,
                        seed=seed + 100_000 * (i + 1) + 20_000 * j + 10_000 * k, **kwargs, **ENV))
    return envs


def clone_teacher(agent: Agent, *, maps: list[str], bots: list[str], worlds_per_map: int,
                  random_starts: float, steps: int, epochs: int, minibatch: int, lr: float,
                  seed: int, step_threads: int) -> dict:
    """Behaviour cloning: fits the actor's mean to the coordinated planner's decisions on
    the same observations (``vector_env.teacher_actions``), before PPO starts from it.

    The planner drives every world (``planner="coordinated"``, the same maps, bots and
    share of random starts as training); after each step every robot's observation is
    paired with the action its planner decided from it (forward, turn, and tag as 1 or 0).
    An episode's first observation has no decision yet and is left out. The loss is the
    mean squared error of the actor's mean against those actions (the tag fires above 0.5,
    so 1 and 0 are what the mean should give), the tag's errors weighted so that the
    decisions to fire weigh as much as the rest. Returns the samples, the share the planner
    fired in, the loss before and after, and the seconds it took."""
    t0 = time.perf_counter()
    # Seeds apart from training's (seed * 1,000,000 + 100,000 … 330,000).
    envs = map_envs(maps, bots, worlds_per_map, random_starts,
                    seed * 1_000_000 + 400_000, planner="coordinated")
    worlds = sum(e.num_worlds for e in envs)
    for e in envs:
        e.reset()
    pool = concurrent.futures.ThreadPoolExecutor(max(1, step_threads))
    xs, ys = [], []
    # Whether a step's observation is an episode's first (a world that ended the step
    # before starts its next one): no decision was made from it.
    fresh = [np.zeros(e.num_envs, bool) for e in envs]
    for _ in range(max(1, steps // worlds)):
        outs = list(pool.map(lambda e: e.step(np.zeros((e.num_envs, 3), np.float32)), envs))
        for i, (e, (obs, _, term, trunc, _)) in enumerate(zip(envs, outs)):
            keep = ~fresh[i]
            if keep.any():
                xs.append(obs[keep])
                ys.append(e.teacher_actions()[keep])
            fresh[i] = term | trunc
    pool.shutdown()
    x = torch.from_numpy(np.concatenate(xs))
    y = torch.from_numpy(np.concatenate(ys))
    opt = torch.optim.Adam(agent.actor.parameters(), lr=lr, eps=1e-5)
    # The planner fires in a few percent of its decisions: unweighted, the tag's mean would
    # regress below 0.5 everywhere and the clone would never fire. Each class of the tag
    # weighs as much as the other.
    fired = float(y[:, 2].mean())
    tag_weight = torch.where(y[:, 2] > 0.5, 0.5 / max(fired, 1e-6), 0.5 / max(1 - fired, 1e-6))

    def loss_of(idx) -> torch.Tensor:
        err = (agent.mean(x[idx]) - y[idx]) ** 2
        return err[:, :2].mean() + (err[:, 2] * tag_weight[idx]).mean()

    def loss_on_all() -> float:
        with torch.no_grad():
            return float(loss_of(slice(None)))

    before = loss_on_all()
    agent.train()
    for _ in range(epochs):
        perm = torch.randperm(len(x))
        for s in range(0, len(x), minibatch):
            loss = loss_of(perm[s : s + minibatch])
            opt.zero_grad()
            loss.backward()
            opt.step()
    after = loss_on_all()
    return {"samples": len(x), "teacher_fired": fired, "loss_before": before,
            "loss_after": after, "seconds": round(time.perf_counter() - t0, 1)}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default="results/train_team")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--total-steps", type=int, default=5_000_000,
                   help="environment steps (one world, every robot acting) over all training maps")
    p.add_argument("--num-envs", type=int, default=16, help="worlds per training map")
    p.add_argument("--num-steps", type=int, default=128, help="rollout length (steps per world)")
    p.add_argument("--maps", default="office,hallway,maze", help="training maps")
    p.add_argument("--held-out", default="warehouse", help="the map never trained on")
    p.add_argument("--bots", default="wander,evade",
                   help="opponent bots, each on an equal share of every map's worlds")
    p.add_argument("--eval-seeds", type=int, default=100, help="fixed seeds per map, final comparison")
    p.add_argument("--curve-seeds", type=int, default=16, help="fixed seeds per map, learning curve")
    p.add_argument("--eval-every", type=int, default=30, help="updates between curve points")
    p.add_argument("--threads", type=int, default=2,
                   help="torch threads while learning (collecting uses one: the environments' "
                        "own threads have the cores then, and torch's would spin against them)")
    p.add_argument("--step-threads", type=int, default=4,
                   help="Python threads stepping the vector environments at once (each step "
                        "releases the GIL and spreads its worlds over the cores)")
    p.add_argument("--hidden", type=int, default=64)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--gae-lambda", type=float, default=0.95)
    p.add_argument("--epochs", type=int, default=4)
    p.add_argument("--minibatch", type=int, default=2048, help="samples per minibatch")
    p.add_argument("--clip", type=float, default=0.2)
    p.add_argument("--ent-coef", type=float, default=0.0)
    p.add_argument("--vf-coef", type=float, default=0.5)
    p.add_argument("--max-grad-norm", type=float, default=0.5)
    p.add_argument("--log-std", type=float, default=0.0, help="initial log-std of the actions")
    p.add_argument("--team-tag", type=float, default=0.0, help="reward to every robot per tag")
    p.add_argument("--see-bonus", type=float, default=0.002,
                   help="shaping: reward a step in which the robot sees an opponent")
    p.add_argument("--random-starts", type=float, default=0.5,
                   help="share of each training map's worlds starting from random free positions")
    p.add_argument("--mask", default="time,pose,teammates",
                   help="observation parts zeroed before the first layer ('' for none)")
    p.add_argument("--bc-steps", type=int, default=0,
                   help="behaviour cloning first: environment steps of the coordinated planner "
                        "whose decisions the actor is fitted to before PPO (0: none)")
    p.add_argument("--bc-epochs", type=int, default=10, help="passes over the cloning samples")
    p.add_argument("--ticks-per-step", type=int, default=4,
                   help="ticks between decisions in training and evaluation (the server serves "
                        "the shipped team deciding every 2)")
    p.add_argument("--smoke", action="store_true",
                   help="a few hundred steps and a tiny evaluation (CI): checks the pipeline")
    args = p.parse_args()
    if args.smoke:
        args.total_steps = min(args.total_steps, 512)
        args.num_envs, args.num_steps = min(args.num_envs, 2), min(args.num_steps, 32)
        args.eval_seeds, args.curve_seeds, args.eval_every = 2, 2, 2
        args.bc_steps, args.bc_epochs = min(args.bc_steps or 64, 64), min(args.bc_epochs, 2)
    decide_every(args.ticks_per_step)
    os.makedirs(args.out, exist_ok=True)
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    maps = [m for m in args.maps.split(",") if m]
    assert args.held_out not in maps, "the held-out map must not be trained on"
    all_maps = maps + [args.held_out]
    rewards = {"tag": 1.0, "team_tag": args.team_tag, "tick": -0.001}

    bots = [b for b in args.bots.split(",") if b]
    probe_env = lasertag_env.parallel_env(map=maps[0], opponent_bot=bots[0], **ENV)
    layout = probe_env.layout
    obs_dim = layout.size
    det = layout.slices["detections"].start  # present flag of the nearest sighting
    mask = np.ones(obs_dim, np.float32)
    for part in filter(None, args.mask.split(",")):
        mask[layout.slices[part]] = 0.0
    agent = Agent(obs_dim, args.hidden, mask, args.log_std)
    cloned = None
    if args.bc_steps > 0:
        cloned = clone_teacher(agent, maps=maps, bots=bots, worlds_per_map=args.num_envs,
                               random_starts=args.random_starts, steps=args.bc_steps,
                               epochs=args.bc_epochs, minibatch=args.minibatch, lr=args.lr,
                               seed=args.seed, step_threads=args.step_threads)
        print(f"behaviour cloning: {cloned['samples']:,} samples of the coordinated planner, "
              f"loss {cloned['loss_before']:.4f} -> {cloned['loss_after']:.4f} "
              f"({cloned['seconds']:.0f} s)", flush=True)
    opt = torch.optim.Adam(agent.parameters(), lr=args.lr, eps=1e-5)

    envs = map_envs(maps, bots, args.num_envs, args.random_starts, args.seed * 1_000_000,
                    rewards=rewards)
    n_entries = sum(e.num_envs for e in envs)
    worlds = sum(e.num_worlds for e in envs)
    bounds = np.cumsum([0] + [e.num_envs for e in envs])
    T = args.num_steps
    updates = max(1, args.total_steps // (worlds * T))
    obs_buf = torch.zeros(T, n_entries, obs_dim)
    act_buf = torch.zeros(T, n_entries, 3)
    logp_buf = torch.zeros(T, n_entries)
    val_buf = torch.zeros(T, n_entries)
    rew_buf = np.zeros((T, n_entries), np.float32)
    term_buf = np.zeros((T, n_entries), bool)
    trunc_buf = np.zeros((T, n_entries), bool)
    valid_buf = np.zeros((T, n_entries), bool)

    obs = np.concatenate([e.reset()[0] for e in envs])
    prev_done = np.zeros(n_entries, bool)
    env_steps = 0
    curve: list[dict] = []
    t0 = time.perf_counter()
    curve_seeds = [CURVE_SEED + i for i in range(args.curve_seeds)]
    ep_returns: list[float] = []
    ep_ret = np.zeros(n_entries)
    # Wall seconds of collecting (policy forward passes and environment steps) and of
    # learning (GAE and the PPO epochs), evaluations left out: the training loop's own speed.
    collect_s = learn_s = 0.0
    stepper = concurrent.futures.ThreadPoolExecutor(max(1, args.step_threads))

    def evaluate(update: int) -> None:
        actor = mean_actor(agent.exported())
        row = {"update": update, "env_steps": env_steps,
               "wall_s": round(time.perf_counter() - t0, 1)}
        for m in all_maps:
            for b in bots:
                r = play(m, curve_seeds, b, actor)
                row[f"{m}_{b}_return"] = round(float(r["return"].mean()), 4)
                row[f"{m}_{b}_captured"] = round(float(np.isfinite(r["time"]).mean()), 4)
                row[f"{m}_{b}_median_s"] = round(float(np.median(np.minimum(r["time"], LIMIT_S))), 1)
            for k in ("return", "captured"):
                row[f"{m}_{k}"] = round(float(np.mean([row[f"{m}_{b}_{k}"] for b in bots])), 4)
        train_ret = np.mean([row[f"{m}_return"] for m in maps])
        train_cap = np.mean([row[f"{m}_captured"] for m in maps])
        row["train_return"], row["train_captured"] = round(float(train_ret), 4), round(float(train_cap), 4)
        row["train_episode_return"] = round(float(np.mean(ep_returns[-200:])), 4) if ep_returns else ""
        row["std"] = " ".join(f"{s:.3f}" for s in agent.log_std.exp().tolist())
        curve.append(row)
        h = args.held_out
        print(f"update {update:4d}/{updates}  {env_steps:10,d} steps  {row['wall_s']:6.0f} s  "
              f"train maps: return {train_ret:6.3f} captured {train_cap:4.0%}  "
              f"{h}: return {row[f'{h}_return']:6.3f} captured {row[f'{h}_captured']:4.0%} "
              f"median " + " ".join(f"{b} {row[f'{h}_{b}_median_s']:4.1f} s" for b in bots)
              + f"  std {row['std']}", flush=True)

    print(f"PPO: {updates} updates of {worlds} worlds x {ENV['robots']} robots x {T} steps "
          f"({n_entries * T:,} samples) on {', '.join(maps)}; held out: {args.held_out}; "
          f"observation {obs_dim} values", flush=True)
    evaluate(0)
    for update in range(1, updates + 1):
        frac = 1.0 - (update - 1) / updates
        for g in opt.param_groups:
            g["lr"] = frac * args.lr
        agent.eval()
        torch.set_num_threads(1)
        t_collect = time.perf_counter()
        for t in range(T):
            obs_t = torch.from_numpy(obs)
            with torch.no_grad():
                action, logp, _, value = agent.act(obs_t)
            obs_buf[t], act_buf[t], logp_buf[t], val_buf[t] = obs_t, action, logp, value
            valid_buf[t] = ~prev_done
            a = action.numpy()
            parts = [a[bounds[i] : bounds[i + 1]] for i in range(len(envs))]
            outs = list(stepper.map(lambda e, x: e.step(x), envs, parts))
            obs = np.concatenate([o[0] for o in outs])
            rew = np.concatenate([o[1] for o in outs]).astype(np.float32)
            term = np.concatenate([o[2] for o in outs])
            trunc = np.concatenate([o[3] for o in outs])
            valid = ~prev_done
            # Shaping, for a step the robot took: it sees an opponent after it.
            rew += args.see_bonus * (obs[:, det] > 0) * valid
            rew_buf[t] = rew * valid
            term_buf[t], trunc_buf[t] = term & valid, trunc & valid
            ep_ret += rew_buf[t]
            ended = (term | trunc) & valid
            if ended.any():
                ep_returns.extend(ep_ret[ended].tolist())
                ep_ret[ended] = 0.0
            prev_done = term | trunc
            env_steps += int(valid.reshape(-1, ENV["robots"])[:, 0].sum())

        t_learn = time.perf_counter()
        collect_s += t_learn - t_collect
        torch.set_num_threads(args.threads)

        # GAE(λ) per robot; a capture ends the chain with value 0, a truncation with the
        # value of the episode's last observation (the next sample's, which is not trained on).
        with torch.no_grad():
            next_value = agent.value(torch.from_numpy(obs)).numpy()
        values = val_buf.numpy()
        adv = np.zeros((T, n_entries), np.float32)
        last = np.zeros(n_entries, np.float32)
        for t in reversed(range(T)):
            nv = next_value if t == T - 1 else values[t + 1]
            nv = np.where(term_buf[t], 0.0, nv)
            delta = rew_buf[t] + args.gamma * nv - values[t]
            cont = ~(term_buf[t] | trunc_buf[t])
            last = delta + args.gamma * args.gae_lambda * cont * last
            adv[t] = last
        returns = adv + values

        keep = torch.from_numpy(valid_buf.reshape(-1))
        b_obs = obs_buf.reshape(-1, obs_dim)[keep]
        b_act = act_buf.reshape(-1, 3)[keep]
        b_logp = logp_buf.reshape(-1)[keep]
        b_adv = torch.from_numpy(adv.reshape(-1))[keep]
        b_ret = torch.from_numpy(returns.reshape(-1))[keep]
        b_val = val_buf.reshape(-1)[keep]
        n = b_obs.shape[0]
        agent.train()
        clipfracs = []
        for _ in range(args.epochs):
            perm = torch.randperm(n)
            for s in range(0, n, args.minibatch):
                mb = perm[s : s + args.minibatch]
                _, logp, ent, v = agent.act(b_obs[mb], b_act[mb])
                ratio = (logp - b_logp[mb]).exp()
                a_mb = b_adv[mb]
                a_mb = (a_mb - a_mb.mean()) / (a_mb.std() + 1e-8)
                pg = torch.max(-a_mb * ratio,
                               -a_mb * ratio.clamp(1 - args.clip, 1 + args.clip)).mean()
                v_clip = b_val[mb] + (v - b_val[mb]).clamp(-args.clip, args.clip)
                vl = 0.5 * torch.max((v - b_ret[mb]) ** 2, (v_clip - b_ret[mb]) ** 2).mean()
                loss = pg - args.ent_coef * ent.mean() + args.vf_coef * vl
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                opt.step()
                clipfracs.append(((ratio - 1).abs() > args.clip).float().mean().item())
        learn_s += time.perf_counter() - t_learn
        if update % args.eval_every == 0 or update == updates:
            print(f"    value loss {vl.item():.4f}  clip fraction {np.mean(clipfracs):.3f}  "
                  f"training episodes' mean return (shaped, per robot) "
                  f"{np.mean(ep_returns[-200:]) if ep_returns else float('nan'):.3f}", flush=True)
            print(f"    {speed_line(env_steps, collect_s, learn_s)}", flush=True)
            evaluate(update)
    train_s = time.perf_counter() - t0

    # Save, export and check.
    seq = agent.exported()
    torch.save({"actor": agent.actor.state_dict(), "critic": agent.critic.state_dict(),
                "log_std": agent.log_std.detach(), "mask": agent.mask, "args": vars(args),
                "obs_dim": obs_dim}, os.path.join(args.out, "policy.pt"))
    onnx_info = export_onnx(seq, obs_dim, os.path.join(args.out, "policy.onnx"),
                            b_obs[:64].numpy())
    print(f"policy.onnx: {onnx_info['bytes']:,} bytes, operators {' '.join(onnx_info['ops'])}, "
          f"input {onnx_info['input']}, output {onnx_info['output']}, "
          f"|onnx - torch| <= {onnx_info['max_abs_diff']:.1e}", flush=True)

    # The learning curve.
    with open(os.path.join(args.out, "curve.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(curve[0]))
        w.writeheader()
        w.writerows(curve)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = [c["env_steps"] for c in curve]
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(10, 3.8), dpi=120)
    h = args.held_out
    ax.plot(x, [c[f"{h}_return"] for c in curve], marker="o", label=f"{h} (held-out map)")
    ax.plot(x, [c["train_return"] for c in curve], marker=".", label="training maps (mean)")
    ax.set_xlabel("environment steps (one world, both robots acting, 4 ticks)")
    ax.set_ylabel("mean return, held-out seeds")
    ax.legend(fontsize=8)
    for b in bots:
        ax2.plot(x, [c[f"{h}_{b}_median_s"] for c in curve], marker="o",
                 label=f"{h} (held-out map), {b}")
    for m in maps:
        for b in bots:
            ax2.plot(x, [c[f"{m}_{b}_median_s"] for c in curve], marker=".", alpha=0.6,
                     label=f"{m}, {b}")
    ax2.set_xlabel("environment steps")
    ax2.set_ylabel(f"median capture time, s (a miss counts {LIMIT_S:.0f} s)")
    ax2.set_ylim(0, LIMIT_S + 2)
    ax2.legend(fontsize=7, ncol=2)
    fig.suptitle(f"PPO, shared 2x{args.hidden} tanh policy: 2 robots v 1 bot ({', '.join(bots)}); "
                 f"trained on {', '.join(maps)}", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "learning_curve.png"))

    # Capture times on fixed seeds: the learned policy and the paper's planners, same matches.
    eval_seeds = [EVAL_SEED + i for i in range(args.eval_seeds)]
    actor = mean_actor(seq)
    names = ["learned", "baseline", "coordinated"]
    times = {}
    for m in all_maps:
        for b in bots:
            times[m, b] = {
                "learned": play(m, eval_seeds, b, actor)["time"],
                "baseline": play(m, eval_seeds, b, planner="baseline")["time"],
                "coordinated": play(m, eval_seeds, b, planner="coordinated")["time"]}
    with open(os.path.join(args.out, "capture_times.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["map", "bot", "held_out", "seed", *names])
        for (m, b), t in times.items():
            for i, s in enumerate(eval_seeds):
                w.writerow([m, b, int(m == h), s, *(f"{t[k][i]:.1f}" if np.isfinite(t[k][i])
                                                    else "" for k in names)])
    summary = {}
    print(f"\ncapture times on {len(eval_seeds)} fixed seeds per map and bot ({EVAL_SEED}-"
          f"{EVAL_SEED + len(eval_seeds) - 1}), {LIMIT_S:.0f} s limit; medians count a capture not "
          f"made as the limit; p: two-sided Wilcoxon signed-rank, learned v planner, per seed")
    print(f"{'map':18} {'bot':7} {'learned':>16} {'baseline':>16} {'coordinated':>16} {'L/B':>5} "
          f"{'p':>8} {'L/C':>5} {'p':>8}")
    for (m, b), t in times.items():
        capped = {k: np.minimum(t[k], LIMIT_S) for k in names}
        med = {k: float(np.median(capped[k])) for k in names}
        cap = {k: float(np.isfinite(t[k]).mean()) for k in names}
        pb, _ = wilcoxon(capped["learned"], capped["baseline"])
        pc, _ = wilcoxon(capped["learned"], capped["coordinated"])
        summary[f"{m}/{b}"] = {"held_out": m == h, "median_s": med, "captured": cap,
                               "ratio_baseline": med["learned"] / med["baseline"],
                               "ratio_coordinated": med["learned"] / med["coordinated"],
                               "p_baseline": pb, "p_coordinated": pc}
        cell = {k: f"{cap[k]:4.0%} {med[k]:5.1f} s" for k in names}
        label = m + (" (held out)" if m == h else "")
        r = summary[f"{m}/{b}"]
        print(f"{label:18} {b:7} {cell['learned']:>16} {cell['baseline']:>16} "
              f"{cell['coordinated']:>16} {r['ratio_baseline']:5.2f} {pb:8.2g} "
              f"{r['ratio_coordinated']:5.2f} {pc:8.2g}")
    try:
        rev = subprocess.run(["git", "log", "-1", "--format=%H", "--", __file__],
                             capture_output=True, text=True, cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", __file__], capture_output=True,
                               text=True, cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
    except OSError:
        rev, dirty = "", ""
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump({"args": vars(args), "maps": maps, "held_out": h, "env": ENV,
                   "env_steps": env_steps, "updates": updates, "train_wall_s": round(train_s, 1),
                   "collect_s": round(collect_s, 1), "learn_s": round(learn_s, 1),
                   "steps_per_s": speeds(env_steps, collect_s, learn_s),
                   "total_wall_s": round(time.perf_counter() - t0, 1), "onnx": onnx_info,
                   "behaviour_cloning": cloned,
                   "script_revision": rev or "uncommitted", "script_modified": bool(dirty),
                   "results": summary}, f, indent=1)
    print(f"\n{speed_line(env_steps, collect_s, learn_s)}")
    print(f"{env_steps:,} environment steps in {train_s:.0f} s of training; "
          f"{time.perf_counter() - t0:.0f} s in all; files in {args.out}")


if __name__ == "__main__":
    main()
