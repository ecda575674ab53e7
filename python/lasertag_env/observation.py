"""The fixed-shape observation vector of one robot, built from the server's observation.

Layout (float32, in this order; ``layout.slices`` names each part):

===============  ===========  =================================================================
part             length       values
===============  ===========  =================================================================
``scan``         181          laser ranges / 8 m, in [0, 1], beam i at bearing (i - 90)°
                              (right to left); all 0 while the robot is frozen (it senses
                              nothing then)
``pose``         4            the robot's own estimate: x / width, y / height (clipped to
                              [0, 1]), cos θ, sin θ
``spread``       1            the estimate's standard deviation in metres, saturated at 1 m
``status``       2            tag_ready (1 when the tag device would fire next tick), frozen
``time``         1            steps taken / max_steps, in [0, 1] (without max_steps:
                              the match's time / its time limit)
``detections``   3 × K        the K nearest anonymous sightings of opponents, nearest first:
                              present (1 or 0), range / 8 m, bearing / (π/2) in [-1, 1];
                              absent ones are all 0
``teammates``    6 × (R - 1)  each other robot in id order: present (1 once the radio has
                              delivered it), x / width, y / height, cos θ, sin θ,
                              age / 100 ticks (saturated at 1)
===============  ===========  =================================================================

Everything comes from what the robot knows (its observation), never from ground truth.
Landmark sightings and odometry are not in the vector (the estimate already uses them);
the raw observation is in each step's ``infos[agent]["observation"]``.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

__all__ = ["ObservationLayout", "LASER_RANGE", "BEAMS"]

LASER_RANGE = 8.0  # metres: the laser's and the opponent detector's reach (game-rules.md)
BEAMS = 181
_HALF_FOV = math.pi / 2
_AGE_SCALE = 100.0


class ObservationLayout:
    """The vector's parts for ``robots`` robots and ``detections`` detection slots."""

    def __init__(self, robots: int, detections: int, width: float, height: float):
        self.robots = robots
        self.k = detections
        self.width = float(width)
        self.height = float(height)
        parts = [
            ("scan", BEAMS, 0.0, 1.0),
            ("pose", 4, -1.0, 1.0),
            ("spread", 1, 0.0, 1.0),
            ("status", 2, 0.0, 1.0),
            ("time", 1, 0.0, 1.0),
            ("detections", 3 * detections, -1.0, 1.0),
            ("teammates", 6 * (robots - 1), -1.0, 1.0),
        ]
        self.slices: dict[str, slice] = {}
        low, high = [], []
        at = 0
        for name, n, lo, hi in parts:
            self.slices[name] = slice(at, at + n)
            low += [lo] * n
            high += [hi] * n
            at += n
        self.size = at
        self.low = np.array(low, dtype=np.float32)
        self.high = np.array(high, dtype=np.float32)
        # Position fractions are in [0, 1] (only the headings' cos and sin are signed); the
        # detections' and teammates' flags, ranges and ages are non-negative.
        p = self.slices["pose"].start
        self.low[p : p + 2] = 0.0
        d = self.slices["detections"].start
        for i in range(detections):
            self.low[d + 3 * i : d + 3 * i + 2] = 0.0
        t = self.slices["teammates"].start
        for i in range(robots - 1):
            base = t + 6 * i
            self.low[base : base + 3] = 0.0
            self.low[base + 5] = 0.0
        self._scan = self.slices["scan"]
        self._inv_range = np.float32(1.0 / LASER_RANGE)
        self._blank_scan = [0.0] * BEAMS  # a frozen robot's scan is empty
        self._no_detection = [0.0, 0.0, 0.0]
        self._no_mates = [0.0] * (6 * (robots - 1))

    def space(self) -> spaces.Box:
        return spaces.Box(self.low, self.high, dtype=np.float32)

    def encode(self, obs: dict, robot: int, time_fraction: float) -> np.ndarray:
        """The vector of robot ``robot`` (its index) from its server observation."""
        # The vector is built as one list and converted once: numpy item assignments cost
        # far more per value than list appends.
        est = obs["estimate"]
        theta = est["theta"]
        tail = [
            est["x"] / self.width, est["y"] / self.height, math.cos(theta), math.sin(theta),
            obs["spread"], 1.0 if obs["tag_ready"] else 0.0, 1.0 if obs["frozen"] else 0.0,
            time_fraction,
        ]
        dets = obs["detections"]
        if len(dets) > 1:
            dets = sorted(dets, key=_range)
        for det in dets[: self.k]:
            tail += (1.0, det["range"] / LASER_RANGE, det["bearing"] / _HALF_FOV)
        tail += self._no_detection * (self.k - min(len(dets), self.k))
        if self.robots > 1:
            mates = self._no_mates[:]
            for m in obs["teammates"]:
                other = int(m["id"][1:])
                slot = other if other < robot else other - 1
                if 0 <= slot < self.robots - 1:
                    th = m["theta"]
                    mates[6 * slot : 6 * slot + 6] = (
                        1.0, m["x"] / self.width, m["y"] / self.height, math.cos(th),
                        math.sin(th), m["age_ticks"] / _AGE_SCALE,
                    )
            tail += mates
        v = np.array((obs["scan"] or self._blank_scan) + tail, dtype=np.float32)
        v[self._scan] *= self._inv_range
        # Estimates a little outside the arena, a spread past 1 m, ages past 100 ticks,
        # ranges past the reach and rounding at the edges all land inside the bounds.
        v.clip(self.low, self.high, out=v)
        return v

    def decode(self, v: np.ndarray) -> dict[str, np.ndarray]:
        """The vector's parts by name (views, not copies), for reading one by hand."""
        return {name: v[..., s] for name, s in self.slices.items()}


def _range(det: dict) -> float:
    return det["range"]
