"""Hand-written robot policies over the server's raw observation (no learning).

They serve as the other robots of the single-agent environment and as the example's
baseline; a policy maps one robot's observation (the dict of ``infos[agent]["observation"]``)
to an action ``[forward, turn, tag]`` in the environments' action space.
"""

from __future__ import annotations

import math

import numpy as np

from .rules import SHIPPED

__all__ = ["idle", "hunter"]

# Aim 2° inside the tag cone, allowing for detection noise.
_AIM = math.radians(SHIPPED["tag"]["half_angle_deg"] - 2.0)
_TAG_RANGE = SHIPPED["tag"]["range"]


def idle(obs: dict) -> np.ndarray:
    """Stands still and never fires."""
    return np.zeros(3, dtype=np.float32)


def hunter(obs: dict) -> np.ndarray:
    """Turns toward the nearest sighting and fires when it is in the cone and in range;
    with nothing in sight, drives toward the most open direction of the laser scan (which
    sweeps the arena's rooms and corridors) and turns away from walls close ahead."""
    if obs["frozen"]:
        return np.zeros(3, dtype=np.float32)
    dets = obs["detections"]
    if dets:
        d = min(dets, key=lambda d: d["range"])
        b = d["bearing"]
        turn = float(np.clip(b * 3.0, -1.0, 1.0))
        forward = 0.0 if d["range"] < 2.0 else (0.3 if abs(b) > 0.5 else 0.8)
        fire = obs["tag_ready"] and abs(b) < _AIM and d["range"] < _TAG_RANGE
        return np.array([forward, turn, 1.0 if fire else 0.0], dtype=np.float32)
    scan = obs["scan"]
    if not scan:
        return np.zeros(3, dtype=np.float32)
    r = np.asarray(scan)
    front = r[75:106].min()
    if front < 0.8:
        # Blocked ahead: turn on the spot toward the freer half of the scan.
        left, right = r[91:].mean(), r[:90].mean()
        return np.array([0.0, 1.0 if left >= right else -1.0, 0.0], dtype=np.float32)
    # Smooth the scan over ±10 beams and head for its longest free stretch, preferring
    # what is ahead so that the robot does not dither between two openings.
    smooth = np.convolve(r, np.ones(21) / 21.0, mode="same")
    bearings = np.radians(np.arange(r.size) - (r.size - 1) / 2)
    best = int(np.argmax(smooth - 0.8 * np.abs(bearings)))
    turn = float(np.clip(bearings[best] * 1.5, -1.0, 1.0))
    forward = 1.0 if front > 2.0 else 0.5
    return np.array([forward, turn, 0.0], dtype=np.float32)
