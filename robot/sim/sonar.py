"""Simulated sonar: the nearest reflecting surface inside each beam's cone, then an ultrasound error model.

The geometry is exact for polygonal worlds: every edge is clipped to the cone and its point nearest
to the transducer is found, so a thin obstacle cannot hide between sample rays.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from robot.config import SimNoise, SonarModel

_EPS = 1e-12
_EDGE_SIGNS = np.array([-1.0, 1.0]).reshape(2, 1, 1)


class Walls:
    """A world's segments (S, 4), with the per-segment terms every ping and every clearance check
    needs computed once."""

    def __init__(self, segments: NDArray[np.float64]) -> None:
        self.segments = segments
        self.x0 = segments[None, :, 0]
        self.y0 = segments[None, :, 1]
        self.dx = segments[None, :, 2] - segments[None, :, 0]
        self.dy = segments[None, :, 3] - segments[None, :, 1]
        self.len2 = self.dx * self.dx + self.dy * self.dy
        self.len2_floor = np.maximum(self.len2, _EPS)
        self.length = np.sqrt(self.len2)
        self._len2_distance = np.maximum(self.len2, 1e-18)  # the floor the clearance has always used

    def distance(self, px: NDArray[np.float64], py: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance (K,) from each point to the nearest segment."""
        dx, dy = self.dx, self.dy
        rx = px[:, None] - self.x0
        ry = py[:, None] - self.y0
        t = np.minimum(np.maximum((rx * dx + ry * dy) / self._len2_distance, 0.0), 1.0)
        return np.hypot(rx - t * dx, ry - t * dy).min(axis=1)


def cone_candidates(
    segments: NDArray[np.float64] | Walls,
    origins: NDArray[np.float64],
    bearings_rad: NDArray[np.float64],
    half_angle_rad: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Distance, incidence angle and position of every edge's nearest point inside every cone.

    ``segments`` (S, 4) rows x0 y0 x1 y1 with free space on the left (or ``Walls`` built from them);
    ``origins`` (n, 2) and ``bearings_rad`` (n,) describe the transducers. Returns ``dist`` (n, S)
    [m], ``inf`` where the edge is outside the cone or faces away, and ``incidence`` (n, S) [rad],
    the angle between the echo path and the edge's normal, and ``points`` (n, S, 2), the nearest
    points relative to the transducers.
    """
    walls = segments if isinstance(segments, Walls) else Walls(segments)
    ox = origins[:, 0:1]
    oy = origins[:, 1:2]
    p0x = walls.x0 - ox  # (n, S), segment start relative to the transducer
    p0y = walls.y0 - oy
    dx, dy = walls.dx, walls.dy  # (1, S): broadcast against (n, S)

    # Only edges whose free side faces the transducer can echo.
    facing = (dx * (-p0y) - dy * (-p0x)) > _EPS

    with np.errstate(divide="ignore", invalid="ignore"):
        # Both edges of the cone at once, the right one (sign -1) first: the half-plane of the edge
        # ray u, sign * cross(u, p) >= 0, keeps the inside.
        sign = _EDGE_SIGNS
        ang = bearings_rad[:, None] - sign * half_angle_rad  # (2, n, 1)
        ux = np.cos(ang)
        uy = np.sin(ang)
        c0 = sign * (ux * p0y - uy * p0x)
        c1 = sign * (ux * dy - uy * dx)
        root = -c0 / c1
        pos = c1 > _EPS
        neg = c1 < -_EPS
        # The segment's stretch inside both: from the largest entry (at least 0) to the smallest
        # exit (at most 1), taken edge after edge.
        lo = np.where(pos, root, -np.inf)
        hi = np.where(neg, root, np.inf)
        t_lo = np.maximum(np.maximum(np.zeros_like(p0x), lo[0]), lo[1])
        t_hi = np.minimum(np.minimum(np.ones_like(p0x), hi[0]), hi[1])
        parallel_outside = ~(pos | neg) & (c0 < 0)
        feasible = facing & ~parallel_outside[0] & ~parallel_outside[1] & (t_lo <= t_hi)

        # np.clip's arithmetic (max, then min) without its overhead.
        t_star = np.minimum(np.maximum(-(p0x * dx + p0y * dy) / walls.len2_floor, t_lo), t_hi)
        qx = p0x + t_star * dx
        qy = p0y + t_star * dy
        dist = np.hypot(qx, qy)
        dist = np.where(feasible, dist, np.inf)
        cos_inc = np.abs(qx * (-dy) + qy * dx) / (walls.length * np.maximum(dist, _EPS))
    incidence = np.arccos(np.minimum(np.maximum(cos_inc, 0.0), 1.0))
    return dist, incidence, np.stack([qx, qy], axis=-1)


def ray_blocked(segments: NDArray[np.float64], ox: float, oy: float, px: float, py: float, skip: int) -> bool:
    """Whether the straight path from (ox, oy) to (px, py) crosses any segment but ``skip`` before it ends."""
    ax, ay = segments[:, 0], segments[:, 1]
    ex, ey = segments[:, 2] - ax, segments[:, 3] - ay
    rx, ry = px - ox, py - oy
    denom = rx * ey - ry * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((ax - ox) * ey - (ay - oy) * ex) / denom  # along the path
        u = ((ax - ox) * ry - (ay - oy) * rx) / denom  # along the segment
    hit = (np.abs(denom) > 1e-12) & (t > 1e-6) & (t < 1.0 - 1e-6) & (u >= 0.0) & (u <= 1.0)
    hit[skip] = False
    return bool(hit.any())


def specular_miss_probability(incidence_rad: NDArray[np.float64], noise: SimNoise) -> NDArray[np.float64]:
    """Chance that an echo at this incidence is lost: 0 below onset, ramping to the max at full."""
    onset = math.radians(noise.specular_onset_deg)
    full = math.radians(noise.specular_full_deg)
    if full <= onset:
        ramp = (incidence_rad >= onset).astype(float)
    else:  # np.clip's arithmetic (max, then min) without its overhead
        ramp = np.minimum(np.maximum((incidence_rad - onset) / (full - onset), 0.0), 1.0)
    return noise.specular_miss_prob * ramp


def simulate_ranges(
    dist: NDArray[np.float64],
    incidence: NDArray[np.float64],
    model: SonarModel,
    noise: SimNoise,
    rng: np.random.Generator,
    occluded: Callable[[int, int], bool] | None = None,
) -> NDArray[np.float64]:
    """Turn per-edge candidates (n, S) into one reading per transducer [m].

    The reading is the nearest edge whose echo is not lost to specular reflection, with range noise,
    quantisation, short false echoes and dropouts. When the nearest echo is lost, a farther surface
    may answer (as multipath does), but only one in the open: ``occluded(i, j)`` says whether edge
    j's nearest point is hidden from transducer i behind something else, since sound does not pass
    through solid objects. ``max_range_m`` means no echo.
    """
    n = dist.shape[0]
    answers = rng.random(dist.shape) >= specular_miss_probability(incidence, noise)
    heard = np.where(answers, dist, np.inf)
    true_range = heard.min(axis=1) if heard.shape[1] else np.full(n, np.inf)
    if occluded is not None and heard.shape[1]:
        nearest = dist.min(axis=1)
        for i in np.flatnonzero(np.isfinite(true_range) & (true_range > nearest)):
            true_range[i] = np.inf
            for j in np.argsort(heard[i]):
                if not np.isfinite(heard[i, j]):
                    break
                if not occluded(int(i), int(j)):
                    true_range[i] = heard[i, j]
                    break
    sigma = noise.range_noise_m + noise.range_noise_frac * np.where(np.isfinite(true_range), true_range, 0.0)
    reading = true_range + sigma * rng.standard_normal(n)

    false_echo = rng.random(n) < noise.false_echo_prob
    # np.clip's arithmetic (max, then min) without its overhead, here and at the end.
    upper = np.minimum(
        np.maximum(np.where(np.isfinite(true_range), true_range, model.max_range_m), model.min_range_m),
        model.max_range_m,
    )
    short = model.min_range_m + (upper - model.min_range_m) * rng.random(n)
    reading = np.where(false_echo, short, reading)
    dropout = rng.random(n) < noise.dropout_prob
    reading = np.where(dropout | ~np.isfinite(reading), model.max_range_m, reading)
    if noise.range_quantum_m > 0:
        reading = np.round(reading / noise.range_quantum_m) * noise.range_quantum_m
    return np.minimum(np.maximum(reading, model.min_range_m), model.max_range_m)
