"""What both backends' environments take and check the same way: reward weights, seeds,
integers and actions."""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = [
    "DEFAULT_REWARDS", "OWN_FIELDS", "MAX_SEED", "check_arguments", "check_int", "check_seed",
    "unpack",
]

DEFAULT_REWARDS = {
    # Each tag the robot makes (an opponent eliminated by its shot).
    "tag": 1.0,
    # Each tag any robot of the team makes, given to every robot (0: no shared credit).
    "team_tag": 0.0,
    # Per simulated tick (20 per second): a small cost of time, so sooner is better.
    "tick": -0.001,
}

# Fields of POST /api/matches the environment sets itself.
OWN_FIELDS = {"map", "robots", "opponents", "opponent_bot", "planner", "clock", "seed"}
MAX_SEED = 2**63 - 1


def unpack(a) -> tuple[float, float, float]:
    if isinstance(a, (str, bytes)):
        # A string of three digits would unpack into three numbers.
        raise TypeError(f"an action is three numbers, not {a!r}")
    # tolist() turns a numpy vector into Python floats in one call (float32 values are
    # exact as float64, so the server gets the policy's numbers unchanged).
    forward, turn, tag = a.tolist() if isinstance(a, np.ndarray) else a
    forward, turn, tag = float(forward), float(turn), float(tag)
    # Out-of-range values are clipped rather than refused (policies' outputs often stray);
    # NaN (no comparison holds), which would make the server refuse the whole step, stands
    # for 0.
    if not -1.0 <= forward <= 1.0:
        forward = 1.0 if forward > 1.0 else -1.0 if forward < -1.0 else 0.0
    if not -1.0 <= turn <= 1.0:
        turn = 1.0 if turn > 1.0 else -1.0 if turn < -1.0 else 0.0
    return forward, turn, tag


def check_int(name: str, value, lo: int | None, hi: int | None) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, not {value!r}")
    if lo is None:
        return
    if value < lo or (hi is not None and value > hi):
        bound = f"in {lo}..={hi}" if hi is not None else f"at least {lo}"
        raise ValueError(f"{name}: {value} must be {bound}")


def check_seed(seed) -> None:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be a non-negative integer, not {seed!r}")
    if not 0 <= seed <= MAX_SEED:
        raise ValueError(f"seed: {seed} must be in 0..=2**63-1")


def check_arguments(*, robots, opponents, ticks_per_step, seed, max_steps, detections,
                    render_mode, render_modes, rewards, match_settings, map) -> None:
    """The types of an environment's arguments (their ranges are the rules' bounds, which
    the environment checks once it has its rules)."""
    for name, value in (("robots", robots), ("opponents", opponents),
                        ("ticks_per_step", ticks_per_step)):
        check_int(name, value, None, None)
    check_seed(seed)
    if max_steps is not None:
        check_int("max_steps", max_steps, 1, None)
    if detections is not None:
        check_int("detections", detections, 0, None)
    if render_mode not in (None, *render_modes):
        raise ValueError(
            f"render_mode {render_mode!r}: the modes are {render_modes} (or None)"
        )
    unknown = set(rewards or {}) - set(DEFAULT_REWARDS)
    if unknown:
        raise ValueError(
            f"rewards: unknown weight(s) {sorted(unknown)}; the weights are {sorted(DEFAULT_REWARDS)}"
        )
    for name, weight in (rewards or {}).items():
        if isinstance(weight, bool) or not isinstance(weight, numbers.Real):
            raise TypeError(f"rewards.{name} must be a number, not {weight!r}")
        if not math.isfinite(weight):
            raise ValueError(f"rewards.{name}: {weight} must be finite")
    clash = set(match_settings or {}) & OWN_FIELDS
    if clash:
        raise ValueError(
            f"match_settings: {sorted(clash)} are arguments of the environment, not settings"
        )
    if not isinstance(map, (str, dict)):
        raise TypeError(f"map must be a map name or a map object, not {type(map).__name__}")

