"""RGB frames of a match, drawn with numpy alone from the map and the ground-truth state.

A frame is small (20 pixels per metre: office is 480 × 320) and cheap: the walls are
rasterised once per map, and each frame copies that background and draws a few discs,
heading lines and the robots' laser endpoints. Pillow or pygame would add a dependency for
what a few array operations do.
"""

from __future__ import annotations

import math

import numpy as np

from .rules import SHIPPED

__all__ = ["Renderer", "check_scale", "MAX_PIXELS"]

BACKGROUND = (246, 246, 242)
WALL = (60, 60, 66)
ROBOT = (40, 110, 220)
ROBOT_FROZEN = (150, 185, 235)
OPPONENT = (220, 60, 50)
TAGGED = (175, 175, 175)
LASER = (60, 170, 90)
HEADING = (20, 20, 20)
AGENT_RADIUS = SHIPPED["agent_radius"]  # metres
#: The most pixels a frame may have: 10,000 × 10,000 (300 MB), the largest map (500 m a
#: side) at the default scale.
MAX_PIXELS = 100_000_000


def check_scale(map_def: dict, ppm) -> None:
    """Raises ``ValueError`` when ``ppm`` (pixels per metre) is not a positive finite number
    or would make a frame of ``map_def`` larger than :data:`MAX_PIXELS`: the environments
    check it at construction, before the first frame allocates anything."""
    if isinstance(ppm, bool) or not isinstance(ppm, (int, float, np.integer, np.floating)):
        raise TypeError(f"pixels_per_metre must be a number, not {ppm!r}")
    if not (0 < ppm and math.isfinite(ppm)):
        raise ValueError(f"pixels_per_metre: {ppm} must be finite and above 0")
    try:
        w = max(1, round(float(map_def["width"]) * ppm))
        h = max(1, round(float(map_def["height"]) * ppm))
    except (KeyError, TypeError, ValueError, OverflowError):
        return  # a map without a finite size, which the map's own checks refuse
    if w * h > MAX_PIXELS:
        raise ValueError(
            f"pixels_per_metre: {ppm} makes a frame of {w} × {h} pixels, at most "
            f"{MAX_PIXELS:,}"
        )


class Renderer:
    """Draws frames of one map at ``ppm`` pixels per metre."""

    def __init__(self, map_def: dict, ppm: float = 20.0):
        self.ppm = float(ppm)
        self.width_m = float(map_def["width"])
        self.height_m = float(map_def["height"])
        self.w = max(1, int(round(self.width_m * self.ppm)))
        self.h = max(1, int(round(self.height_m * self.ppm)))
        bg = np.empty((self.h, self.w, 3), dtype=np.uint8)
        bg[:] = BACKGROUND
        # Pixel centres in map coordinates (y grows up in the map, down in the image).
        xs = (np.arange(self.w) + 0.5) / self.ppm
        ys = self.height_m - (np.arange(self.h) + 0.5) / self.ppm
        for poly in map_def.get("obstacles", []):
            self._fill_polygon(bg, np.asarray(poly, dtype=np.float64), xs, ys, WALL)
        border = max(1, int(round(0.1 * self.ppm)))
        bg[:border, :] = WALL
        bg[-border:, :] = WALL
        bg[:, :border] = WALL
        bg[:, -border:] = WALL
        self.background = bg

    def _fill_polygon(self, img, poly, xs, ys, colour) -> None:
        # Even-odd rule on the pixel centres inside the polygon's bounding box.
        x0, y0 = poly.min(axis=0)
        x1, y1 = poly.max(axis=0)
        cols = np.nonzero((xs >= x0) & (xs <= x1))[0]
        rows = np.nonzero((ys >= y0) & (ys <= y1))[0]
        if cols.size == 0 or rows.size == 0:
            # Thinner than a pixel: still draw it, as a line along its longest extent.
            for a, b in zip(poly, np.roll(poly, -1, axis=0)):
                self.line(img, a, b, colour)
            return
        px = xs[cols][None, :]
        py = ys[rows][:, None]
        inside = np.zeros((rows.size, cols.size), dtype=bool)
        n = len(poly)
        for i in range(n):
            ax, ay = poly[i]
            bx, by = poly[(i + 1) % n]
            if ay == by:
                continue
            crosses = (ay > py) != (by > py)
            x_at = ax + (py - ay) * (bx - ax) / (by - ay)
            inside ^= crosses & (px < x_at)
        img[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1][inside] = colour

    def to_px(self, x: float, y: float) -> tuple[float, float]:
        return x * self.ppm, (self.height_m - y) * self.ppm

    def disc(self, img, x: float, y: float, r: float, colour) -> None:
        cx, cy = self.to_px(x, y)
        rp = r * self.ppm
        c0, c1 = max(0, int(cx - rp)), min(self.w, int(cx + rp) + 2)
        r0, r1 = max(0, int(cy - rp)), min(self.h, int(cy + rp) + 2)
        if c0 >= c1 or r0 >= r1:
            return
        yy, xx = np.mgrid[r0:r1, c0:c1]
        mask = (xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2 <= rp * rp
        img[r0:r1, c0:c1][mask] = colour

    def line(self, img, a, b, colour) -> None:
        ax, ay = self.to_px(*a)
        bx, by = self.to_px(*b)
        n = int(max(abs(bx - ax), abs(by - ay))) + 2
        t = np.linspace(0.0, 1.0, n)
        cols = (ax + (bx - ax) * t).astype(int)
        rows = (ay + (by - ay) * t).astype(int)
        ok = (cols >= 0) & (cols < self.w) & (rows >= 0) & (rows < self.h)
        img[rows[ok], cols[ok]] = colour

    def points(self, img, xs: np.ndarray, ys: np.ndarray, colour) -> None:
        cols = (xs * self.ppm).astype(int)
        rows = ((self.height_m - ys) * self.ppm).astype(int)
        ok = (cols >= 0) & (cols < self.w) & (rows >= 0) & (rows < self.h)
        img[rows[ok], cols[ok]] = colour

    def frame(self, state: dict) -> np.ndarray:
        """An (H, W, 3) uint8 frame of a match state (``GET /api/matches/{id}``)."""
        img = self.background.copy()
        for opp in state.get("opponents", []):
            colour = TAGGED if opp.get("tagged") else OPPONENT
            self.disc(img, opp["x"], opp["y"], AGENT_RADIUS, colour)
            if not opp.get("tagged"):
                self._heading(img, opp)
        for robot in state.get("robots", []):
            scan = robot.get("scan") or []
            if scan:
                # Beam i at bearing (i - 90)° from the robot's true heading; beams at the
                # laser's reach hit nothing and are not drawn.
                r = np.asarray(scan, dtype=np.float64)
                a = robot["theta"] + np.radians(np.arange(r.size) - (r.size - 1) / 2)
                hit = r < 7.99
                self.points(img, robot["x"] + r[hit] * np.cos(a[hit]),
                            robot["y"] + r[hit] * np.sin(a[hit]), LASER)
            colour = ROBOT_FROZEN if robot.get("frozen") else ROBOT
            self.disc(img, robot["x"], robot["y"], AGENT_RADIUS, colour)
            self._heading(img, robot)
        return img

    def _heading(self, img, agent) -> None:
        x, y, th = agent["x"], agent["y"], agent["theta"]
        tip = (x + 0.45 * math.cos(th), y + 0.45 * math.sin(th))
        self.line(img, (x, y), tip, HEADING)
