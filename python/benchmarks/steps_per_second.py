"""Environment steps per second from Python, and where the time goes.

For each count of parallel environments (separate processes, each with its own
environment and match, all on one local server by default) it steps random actions for a
fixed wall time and reports:

- steps/s, in all and per environment;
- the client's CPU time per step (the Python processes: HTTP, JSON, observation vectors);
- the server's CPU time per step (the ``lasertag`` process, from /proc), and of that the
  match's own tick compute (``GET /api/matches/{id}/stats``: the core's step plus the
  frame the match task publishes each tick), the rest being HTTP, JSON and scheduling;
- the load average, since a shared 2-core machine moves every figure.

Then, for one environment, the layers of a step (``--layers``): the bare ``act`` round trip
(the same request body, answer not parsed), with the answer parsed, and the whole
environment step; and PettingZoo's MPE ``simple_tag`` stepped the same way
(``--simple-tag``, from the ``mpe2`` package or, before PettingZoo 1.25, ``pettingzoo.mpe``).

Bounded: each measurement runs ``--seconds`` (default 10) after ``--warmup`` (1 s); the
server it starts is stopped at the end. Example::

    cargo build --release
    python python/benchmarks/steps_per_second.py --envs 1 2 8 --layers --simple-tag
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import time

import numpy as np

import lasertag_env
from lasertag_env.client import Client, loads


def proc_cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process (Linux /proc)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def random_actions(env, n: int, seed: int) -> list[dict]:
    """Pre-drawn actions, so that sampling is not part of what is measured."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        out.append({
            a: np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), float(rng.random() < 0.05)],
                        dtype=np.float32)
            for a in env.possible_agents
        })
    return out


def lasertag_worker(i, url, token, kwargs, warmup, seconds, start, results):
    env = lasertag_env.parallel_env(server=url, admin_token=token, seed=i, **kwargs)
    actions = random_actions(env, 4096, i)
    env.reset()
    start.wait()
    t_end_warm = time.perf_counter() + warmup
    k = 0
    while time.perf_counter() < t_end_warm:
        env.step(actions[k & 4095])
        k += 1
        if not env.agents:
            env.reset()
    ticks = []  # (mean tick µs, ticks measured) of each match stepped

    def tick_stats():
        s = env._client.call("GET", f"/api/matches/{env.match_id}/stats")
        ticks.append((s["tick_us_mean"], s["ticks_measured"]))

    steps = resets = 0
    c0, t0 = time.process_time(), time.perf_counter()
    t_end = t0 + seconds
    while True:
        env.step(actions[k & 4095])
        k += 1
        steps += 1
        if not env.agents:
            tick_stats()
            env.reset()
            resets += 1
        if (steps & 63) == 0 and time.perf_counter() >= t_end:
            break
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    tick_stats()
    # The match task's own compute per tick (its stats cover each match's last 4,096
    # ticks, warm-up included), weighted by the ticks each match measured.
    tick_us = sum(m * n for m, n in ticks) / max(1, sum(n for _, n in ticks))
    env.close()
    results.put({"steps": steps, "resets": resets, "wall": wall, "cpu": cpu,
                 "tick_us": tick_us, "ticks_per_step": kwargs.get("ticks_per_step", 1)})


def mpe_worker(i, _url, _token, kwargs, warmup, seconds, start, results):
    try:
        from mpe2 import simple_tag_v3
    except ImportError:  # PettingZoo before 1.25 shipped MPE itself
        from pettingzoo.mpe import simple_tag_v3
    env = simple_tag_v3.parallel_env(max_cycles=kwargs["max_cycles"])
    env.reset(seed=i)
    rng = np.random.default_rng(i)
    actions = [{a: int(rng.integers(5)) for a in env.possible_agents} for _ in range(4096)]
    start.wait()
    k = 0
    t_end_warm = time.perf_counter() + warmup
    while time.perf_counter() < t_end_warm:
        env.step(actions[k & 4095])
        k += 1
        if not env.agents:
            env.reset()
    steps = resets = 0
    c0, t0 = time.process_time(), time.perf_counter()
    t_end = t0 + seconds
    while True:
        env.step(actions[k & 4095])
        k += 1
        steps += 1
        if not env.agents:
            env.reset()
            resets += 1
        if (steps & 63) == 0 and time.perf_counter() >= t_end:
            break
    results.put({"steps": steps, "resets": resets, "wall": time.perf_counter() - t0,
                 "cpu": time.process_time() - c0, "tick_us": None, "ticks_per_step": 1})


def run(worker, n, url, token, kwargs, args, server_pid=None):
    ctx = mp.get_context("spawn")  # no inherited sockets or threads
    start = ctx.Barrier(n + 1)
    results = ctx.Queue()
    procs = [ctx.Process(target=worker, args=(i, url, token, kwargs, args.warmup, args.seconds,
                                              start, results)) for i in range(n)]
    for p in procs:
        p.start()
    start.wait(timeout=300)
    time.sleep(args.warmup)
    s0 = proc_cpu_s(server_pid) if server_pid else None
    load0 = os.getloadavg()[0]
    out = [results.get(timeout=args.seconds + args.warmup + 300) for _ in procs]
    s1 = proc_cpu_s(server_pid) if server_pid else None
    for p in procs:
        p.join(60)
    steps = sum(r["steps"] for r in out)
    wall = max(r["wall"] for r in out)
    row = {
        "envs": n,
        "steps_per_s": steps / wall,
        "per_env_steps_per_s": steps / wall / n,
        "client_cpu_us_per_step": 1e6 * sum(r["cpu"] for r in out) / steps,
        "resets": sum(r["resets"] for r in out),
        "load_before": load0,
        "load_after": os.getloadavg()[0],
    }
    if s0 is not None:
        # The server's CPU over the measured window (it also covers the last workers'
        # closing requests, a few milliseconds).
        row["server_cpu_us_per_step"] = 1e6 * (s1 - s0) / steps
        ticks = [r["tick_us"] for r in out if r["tick_us"] is not None]
        if ticks:
            row["tick_compute_us_per_step"] = float(np.mean(ticks)) * out[0]["ticks_per_step"]
    return row


def layers(url, token, kwargs, seconds):
    """One environment: the bare act round trip, + JSON parsing, + the whole step."""
    env = lasertag_env.parallel_env(server=url, admin_token=token, seed=0, **kwargs)
    env.reset()
    actions = random_actions(env, 4096, 0)
    body = env._act_body(actions[0])
    client = Client(url, token)
    path = env._act_path
    answer = client.raw("POST", path, body)
    if answer.status != 200:
        raise RuntimeError(f"act answered {answer.status}: {answer.body[:200]!r}")
    size = len(answer.body)
    rows = {}

    def timed(name, fn):
        for _ in range(200):
            fn()
        n = 0
        c0, t0 = time.process_time(), time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            for _ in range(64):
                fn()
            n += 64
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        rows[name] = {"steps_per_s": n / wall, "us_per_step": 1e6 * wall / n,
                      "client_cpu_us_per_step": 1e6 * cpu / n}

    timed("act round trip, answer not parsed", lambda: client.raw("POST", path, body))
    timed("act round trip + JSON parse", lambda: loads(client.raw("POST", path, body).body))
    k = [0]

    def step():
        env.step(actions[k[0] & 4095])
        k[0] += 1
        if not env.agents:
            env.reset()

    timed("whole environment step", step)
    client.close()
    env.close()
    return rows, size


def profile(url, token, kwargs, steps):
    import cProfile
    import io
    import pstats

    env = lasertag_env.parallel_env(server=url, admin_token=token, seed=0, **kwargs)
    env.reset()
    actions = random_actions(env, 4096, 0)
    pr = cProfile.Profile()
    pr.enable()
    for k in range(steps):
        env.step(actions[k & 4095])
        if not env.agents:
            env.reset()
    pr.disable()
    env.close()
    s = io.StringIO()
    pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(15)
    return s.getvalue()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--envs", type=int, nargs="+", default=[1, 2, 8])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--warmup", type=float, default=1.0)
    ap.add_argument("--binary", help="lasertag binary (default: as the package finds it)")
    ap.add_argument("--server", help="a running server's URL instead of a local one "
                    "(with $LASERTAG_ADMIN_TOKEN); its CPU time is not measured then")
    ap.add_argument("--map", default="office")
    ap.add_argument("--robots", type=int, default=2)
    ap.add_argument("--opponents", type=int, default=1)
    ap.add_argument("--ticks-per-step", type=int, default=1)
    ap.add_argument("--match-settings", type=json.loads, default=None,
                    help='extra match fields as JSON, e.g. \'{"localisation": false}\'')
    ap.add_argument("--team-tracker", action="store_true",
                    help="the server's team tracker at its default size (the environment's "
                         "default is its minimum)")
    ap.add_argument("--json-scans", action="store_true",
                    help="scans as JSON numbers (the environment's packed_scans=False)")
    ap.add_argument("--layers", action="store_true", help="time a step's layers (1 env)")
    ap.add_argument("--profile", type=int, default=0, metavar="STEPS",
                    help="cProfile the client over this many steps (1 env)")
    ap.add_argument("--simple-tag", action="store_true", help="also MPE simple_tag")
    ap.add_argument("--simple-tag-cycles", type=int, default=200)
    ap.add_argument("--json", help="write the results here as JSON")
    args = ap.parse_args()

    kwargs = dict(map=args.map, robots=args.robots, opponents=args.opponents,
                  ticks_per_step=args.ticks_per_step, max_steps=None,
                  # Long matches: the measurement is of steps, not of episode starts.
                  time_limit_s=3600, match_settings=args.match_settings,
                  team_tracker=args.team_tracker, packed_scans=not args.json_scans)
    json_parser = "orjson" if loads is not json.loads else "json (stdlib)"
    report = {"machine": {"cpus": os.cpu_count(), "python": sys.version.split()[0],
                          "json": json_parser},
              "settings": {k: v for k, v in kwargs.items() if v is not None}}
    server = None
    if args.server:
        url, token, pid = args.server, os.environ.get("LASERTAG_ADMIN_TOKEN"), None
    else:
        server = lasertag_env.LocalServer(binary=args.binary)
        url, token, pid = server.url, server.admin_token, server.pid
        report["binary"] = str(server.binary)
    try:
        print(f"lasertag: {args.robots} robots, {args.opponents} opponents, {args.map}, "
              f"{args.ticks_per_step} tick(s) per step, {args.seconds:.0f} s each; "
              f"JSON by {json_parser}; load average {os.getloadavg()[0]:.2f}", flush=True)
        print(f"{'envs':>4} {'steps/s':>9} {'per env':>8} {'client CPU':>11} "
              f"{'server CPU':>11} {'of it tick':>11} {'load':>10}")
        report["lasertag"] = []
        for n in args.envs:
            row = run(lasertag_worker, n, url, token, kwargs, args, pid)
            report["lasertag"].append(row)
            print(f"{n:>4} {row['steps_per_s']:>9.0f} {row['per_env_steps_per_s']:>8.0f} "
                  f"{row['client_cpu_us_per_step']:>8.0f} us "
                  f"{row.get('server_cpu_us_per_step', float('nan')):>8.0f} us "
                  f"{row.get('tick_compute_us_per_step', float('nan')):>8.0f} us "
                  f"{row['load_before']:>4.1f}→{row['load_after']:<4.1f}", flush=True)
        if args.layers:
            rows, size = layers(url, token, kwargs, args.seconds)
            report["layers"] = rows
            report["act_answer_bytes"] = size
            print(f"\none environment, layer by layer (act answer {size} bytes):")
            for name, r in rows.items():
                print(f"  {name:<36} {r['steps_per_s']:>7.0f} steps/s  "
                      f"{r['us_per_step']:>6.0f} us/step  client CPU {r['client_cpu_us_per_step']:>5.0f} us")
        if args.profile:
            text = profile(url, token, kwargs, args.profile)
            report["profile"] = text
            print("\nclient profile (cProfile, by own time):\n" + text)
    finally:
        if server is not None:
            server.close()
    if args.simple_tag:
        print(f"\nMPE simple_tag (mpe2 / pettingzoo.mpe), defaults, max_cycles="
              f"{args.simple_tag_cycles}, random discrete actions:")
        print(f"{'envs':>4} {'steps/s':>9} {'per env':>8} {'CPU/step':>9} {'load':>10}")
        report["simple_tag"] = []
        for n in args.envs:
            row = run(mpe_worker, n, None, None, {"max_cycles": args.simple_tag_cycles}, args)
            report["simple_tag"].append(row)
            print(f"{n:>4} {row['steps_per_s']:>9.0f} {row['per_env_steps_per_s']:>8.0f} "
                  f"{row['client_cpu_us_per_step']:>6.0f} us "
                  f"{row['load_before']:>4.1f}→{row['load_after']:<4.1f}", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(report, f, indent=2)


if __name__ == "__main__":
    main()
