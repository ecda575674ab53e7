"""A hand-written policy for the API robots against the built-in coordinated planner.

Trains nothing. For each seed it plays one match with the robots driven from Python by
``lasertag_env.policies.hunter`` (sweep toward open space, turn toward the nearest
sighting, fire when it is in the cone and the device is ready), and the same match (map,
seed, opponents, time limit) with the server's own coordinated planner, stepped with
``POST /api/matches/{id}/step``. It prints each capture time: seconds until every opponent
is tagged, or "-" when the time limit came first.

    cargo build --release
    python python/examples/hand_policy.py --episodes 10
    python python/examples/hand_policy.py --server http://127.0.0.1:8080   # a running server
"""

from __future__ import annotations

import argparse
import os
import statistics

import lasertag_env
from lasertag_env import policies
from lasertag_env.client import Client

TICK_HZ = 20


def hand_policy_capture(env, seed: int) -> float | None:
    obs, infos = env.reset(seed=seed)
    raws = {a: infos[a]["observation"] for a in infos}
    terminated = {}
    while env.agents:
        actions = {a: policies.hunter(raws[a]) for a in env.agents}
        obs, rewards, terminated, truncated, infos = env.step(actions)
        raws = {a: infos[a]["observation"] for a in infos}
    return env.tick / TICK_HZ if all(terminated.values()) else None


def planner_capture(client: Client, match: dict, seed: int) -> float | None:
    summary = client.call("POST", "/api/matches", {**match, "seed": seed,
                                                   "planner": "coordinated", "clock": "manual"})
    path = f"/api/matches/{summary['id']}"
    token = client.token or summary["owner_token"]
    try:
        while True:
            state = client.call("POST", path + "/step", {"ticks": 200}, token=token)
            if state["status"] == "finished":
                return state["time_s"] if state["winner"] == "robots" else None
    finally:
        client.call("DELETE", path, token=token)


def main():
    ap = argparse.ArgumentParser(description="hand policy vs the coordinated planner")
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--map", default="office")
    ap.add_argument("--robots", type=int, default=2)
    ap.add_argument("--opponents", type=int, default=1)
    ap.add_argument("--bot", default="wander", help="opponent bot: wander, evade or idle")
    ap.add_argument("--placement", default="random", help="spawns or random (as the experiments)")
    ap.add_argument("--time-limit", type=float, default=120.0, help="seconds per match")
    ap.add_argument("--server", help="a running server's URL (default: start one)")
    args = ap.parse_args()

    server = None
    if args.server:
        url, token = args.server, os.environ.get("LASERTAG_ADMIN_TOKEN")
    else:
        server = lasertag_env.LocalServer()
        url, token = server.url, server.admin_token
    match = {"map": args.map, "robots": args.robots, "opponents": args.opponents,
             "opponent_bot": args.bot, "placement": args.placement,
             "time_limit_s": args.time_limit}
    env = lasertag_env.parallel_env(
        server=url, admin_token=token, map=args.map, robots=args.robots,
        opponents=args.opponents, opponent_bot=args.bot, max_steps=None,
        time_limit_s=args.time_limit, placement=args.placement,
    )
    client = Client(url, token)
    hand, planned = [], []
    try:
        print(f"{args.map}, {args.robots} robots, {args.opponents} {args.bot} opponent(s), "
              f"{args.placement} starts, time limit {args.time_limit:.0f} s")
        print(f"{'seed':>4}  {'hand policy':>11}  {'coordinated':>11}")
        for seed in range(args.episodes):
            h = hand_policy_capture(env, seed)
            p = planner_capture(client, match, seed)
            hand.append(h)
            planned.append(p)
            print(f"{seed:>4}  {fmt(h):>11}  {fmt(p):>11}", flush=True)
        for name, times in (("hand policy", hand), ("coordinated", planned)):
            got = [t for t in times if t is not None]
            # A match not won counts as the time limit: the median stays a fair comparison
            # when one side misses more (it is then a lower bound).
            median = statistics.median(args.time_limit if t is None else t for t in times)
            print(f"{name}: captured {len(got)}/{len(times)}, median {median:.1f} s")
    finally:
        client.close()
        env.close()
        if server is not None:
            server.close()


def fmt(t: float | None) -> str:
    return "-" if t is None else f"{t:.1f} s"


if __name__ == "__main__":
    main()
