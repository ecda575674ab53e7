"""The fixed-shape observation vector of one robot, built from the server's observation.

Layout (float32, in this order; ``layout.slices`` names each part), with the rules of the
server's ``GET /api/rules`` (the numbers below are its defaults: 181 beams over 180°, an
8 m reach):

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
``teammates``    9 × (R - 1)  each other robot in id order: present (1 once the radio has
                              delivered it), x / width, y / height, cos θ, sin θ,
                              age / 100 ticks (saturated at 1), goal present (1 when the
                              radio delivered where it is going; robots driven by actions
                              announce no goal), goal x / width, goal y / height
``belief_grid``  16           the team belief as this robot holds it: the expected share of
                              the untagged opponents in each cell of an egocentric grid,
                              8 sectors of 45° counter-clockwise from straight ahead nearer
                              than 4 m, then the same 8 farther out (sums to 1 while any is
                              believed untagged)
``belief_paths`` 8            the same mass by the way to walk to it: of the belief within
                              6 m of travel, the expected share of the untagged opponents
                              in each of the 8 sectors of the point 1 m along the shortest
                              path to it (through doors, around walls; sums to at most 1)
``roles``        7 × 2        the 2 untagged roles with the nearest means, nearest first:
                              present, count / opponents, ahead / 10 m, left / 10 m (clipped
                              to [-1, 1]), spread / 5 m, confidence (decays with the time
                              since a sighting confirmed it), ticks looked at in vain / 100
``untagged``     1            the share of the opponents believed untagged
===============  ===========  =================================================================

R robots and K detection slots give 189 + 3K + 9(R - 1) + 39 values with the default
rules (2 robots, 1 slot: 240).

Everything comes from what the robot knows (its observation), never from ground truth.
The belief parts are the observation's ``belief`` object as the server computed it from the
robot's own tracker (rounded to a ten-thousandth), copied as they are.
Landmark sightings and odometry are not in the vector (the estimate already uses them);
the raw observation is in each step's ``infos[agent]["observation"]``.

The server may send a scan packed (``act`` with ``"scans": "hex"``: millimetres as
little-endian ``u16``, in hexadecimal); the layout unpacks it with numpy and puts the ranges back into the
raw observation as the list of metres the JSON would have held, bit for bit, so the vector
and the raw observation are the same either way.
"""

from __future__ import annotations

import math
from binascii import a2b_hex

import numpy as np
from gymnasium import spaces

from .rules import SHIPPED

__all__ = ["ObservationLayout", "LASER_RANGE", "BEAMS"]

#: Metres: the laser's and the opponent detector's reach, in the shipped rules (a layout
#: takes its server's).
LASER_RANGE = float(SHIPPED["laser"]["range"])
#: Beams of a scan, in the shipped rules (a layout takes its server's).
BEAMS = int(SHIPPED["laser"]["beams"])
_AGE_SCALE = 100.0
#: Values of one teammate's slot.
_MATE = 9
#: Untagged roles summarised in the belief part.
_ROLE_SLOTS = 2


class ObservationLayout:
    """The vector's parts for ``robots`` robots and ``detections`` detection slots, for
    the sensors of ``rules`` (the server's ``GET /api/rules``; the shipped rules when
    None)."""

    def __init__(self, robots: int, detections: int, width: float, height: float,
                 rules: dict | None = None):
        laser = (rules or SHIPPED)["laser"]
        self.beams = int(laser["beams"])
        self.laser_range = float(laser["range"])
        self._mm_range = np.float32(1000.0 * self.laser_range)
        self._half_fov = math.radians(laser["fov_deg"]) / 2
        self.robots = robots
        self.k = detections
        self.width = float(width)
        self.height = float(height)
        parts = [
            ("scan", self.beams, 0.0, 1.0),
            ("pose", 4, -1.0, 1.0),
            ("spread", 1, 0.0, 1.0),
            ("status", 2, 0.0, 1.0),
            ("time", 1, 0.0, 1.0),
            ("detections", 3 * detections, -1.0, 1.0),
            ("teammates", _MATE * (robots - 1), -1.0, 1.0),
            ("belief_grid", 16, 0.0, 1.0),
            ("belief_paths", 8, 0.0, 1.0),
            ("roles", 7 * _ROLE_SLOTS, -1.0, 1.0),
            ("untagged", 1, 0.0, 1.0),
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
            base = t + _MATE * i
            self.low[base : base + 3] = 0.0
            self.low[base + 5 : base + _MATE] = 0.0
        r = self.slices["roles"].start
        for i in range(_ROLE_SLOTS):
            self.low[r + 7 * i : r + 7 * i + 2] = 0.0
            self.low[r + 7 * i + 4 : r + 7 * i + 7] = 0.0
        self._no_detection = [0.0, 0.0, 0.0]
        self._no_mates = [0.0] * (_MATE * (robots - 1))

    def space(self) -> spaces.Box:
        return spaces.Box(self.low, self.high, dtype=np.float32)

    def encode(self, obs: dict, robot: int, time_fraction: float) -> np.ndarray:
        """The vector of robot ``robot`` (its index) from its server observation."""
        v = np.empty((1, self.size), dtype=np.float32)
        self._scans_into(v, [obs])
        v[0, self.beams:] = self._tail(obs, robot, time_fraction)
        return self._bound(v)[0]

    def encode_all(self, observations: list, time_fraction: float,
                   robots: list | None = None) -> np.ndarray:
        """The vectors of robots ``robots`` (default 0, 1, …; the observations in that
        order), as the rows of one array: a few numpy calls for the whole team rather than a
        few per robot."""
        v = np.empty((len(observations), self.size), dtype=np.float32)
        self._scans_into(v, observations)
        index = robots if robots is not None else range(len(observations))
        v[:, self.beams:] = [self._tail(o, i, time_fraction) for i, o in zip(index, observations)]
        return self._bound(v)

    def _bound(self, v: np.ndarray) -> np.ndarray:
        # Estimates a little outside the arena, a spread past 1 m, ages past 100 ticks,
        # ranges past the reach and rounding at the edges all land inside the bounds.
        np.maximum(v, self.low, out=v)
        np.minimum(v, self.high, out=v)
        return v

    def _scans_into(self, v: np.ndarray, observations: list) -> None:
        """Each observation's scan / the laser's reach into its row of ``v``. Packed scans (hex) are
        unpacked, and the raw observation gets the list of metres the JSON would have
        held."""
        beams = self.beams
        scans = [o["scan"] for o in observations]
        if isinstance(scans[0], str):
            packed = [a2b_hex(s) for s in scans]
            if all(len(b) == 2 * beams for b in packed):
                mm = np.frombuffer(b"".join(packed), dtype="<u2").reshape(len(packed), beams)
                # millimetres / 8000 in float32 is exactly the float32 of (the JSON's
                # metres, mm / 1000 in float64) / 8: checked for every u16 in the tests.
                np.divide(mm, self._mm_range, out=v[:, :beams])
                for o, metres in zip(observations, (mm / 1000.0).tolist()):
                    o["scan"] = metres
                return
            # Some robot is frozen (its scan empty): row by row.
            scans = []
            for o, b in zip(observations, packed):
                o["scan"] = (np.frombuffer(b, dtype="<u2") / 1000.0).tolist()
                scans.append(o["scan"])
        if all(len(s) == beams for s in scans):
            np.divide(scans, self.laser_range, out=v[:, :beams])
            return
        for row, s in zip(v, scans):
            if s:
                np.divide(s, self.laser_range, out=row[:beams])
            else:  # a frozen robot senses nothing
                row[:beams] = 0.0

    def _tail(self, obs: dict, robot: int, time_fraction: float) -> list:
        """Everything after the scan, as a list (numpy item assignments cost far more per
        value than list appends)."""
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
            tail += (1.0, det["range"] / self.laser_range, det["bearing"] / self._half_fov)
        tail += self._no_detection * (self.k - min(len(dets), self.k))
        if self.robots > 1:
            mates = self._no_mates[:]
            for m in obs["teammates"]:
                other = int(m["id"][1:])
                slot = other if other < robot else other - 1
                if 0 <= slot < self.robots - 1:
                    th = m["theta"]
                    goal = m.get("goal")
                    mates[_MATE * slot : _MATE * slot + _MATE] = (
                        1.0, m["x"] / self.width, m["y"] / self.height, math.cos(th),
                        math.sin(th), m["age_ticks"] / _AGE_SCALE,
                        *((1.0, goal[0] / self.width, goal[1] / self.height) if goal
                          else (0.0, 0.0, 0.0)),
                    )
            tail += mates
        belief = obs["belief"]
        tail += belief["grid"]
        tail += belief["paths"]
        for role in belief["roles"]:
            tail += role
        tail.append(belief["untagged"])
        return tail

    def decode(self, v: np.ndarray) -> dict[str, np.ndarray]:
        """The vector's parts by name (views, not copies), for reading one by hand."""
        return {name: v[..., s] for name, s in self.slices.items()}


def _range(det: dict) -> float:
    return det["range"]
