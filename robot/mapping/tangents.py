"""Straight walls from sonar echoes: the lines that many echoes are tangent to.

An echo at range r says the nearest surface in the cone touches the circle of radius r around the
transducer. A flat wall seen from several places is tangent to all their circles, and each echo
votes for every line tangent to its circle inside its cone, so the wall is where the votes pile up
in (normal direction, distance) space: a Hough transform, as in Tardós et al. (2002), "Robust
mapping and localization in indoor environments using sonar data". A point target (a corner, a
chair leg) does not pile votes up this way unless the robot drove straight at it, and then the
echoes meet the line at one point, which the minimum length rules out.

A map cell that a wall at an angle clips at a corner can look free all the way in the evidence grid:
beams that meet the wall at a glancing angle hear nothing and clear the floor past it, and the
echoes that do come back place it on circular arcs, which touch a flat wall at one point only. The
lines found here say where the wall runs, so the map cells they cut into, by more than a margin,
are blocked. They are found once, when the run's map is finalised (the explorer never sees them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from robot.grid import GridSpec


class TangentParams(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = True
    # The accumulator holds 360 / theta_step_deg x (the echoes' spread of distances / d_step_m) bins
    # of 8 bytes: at the lower bounds about 70 MB in a 20 x 20 m room.
    theta_step_deg: float = Field(default=1.0, ge=0.25, le=10.0)  # accumulator bin, normal direction
    d_step_m: float = Field(default=0.02, ge=0.005)  # accumulator bin, distance
    max_range_m: float = Field(default=1.5, gt=0.0)  # only echoes this short vote
    # ... but echoes up to touch_range_m count where they touch a box edge (``touches``): a robot
    # that mapped a box wall's floor from farther than max_range_m away and never drove closer would
    # otherwise leave the edge untouched, and the final map would not hold its face free (a 7 x 5 m
    # room at 0.1 m, seed 1: the right wall's cells black down the last column, F1 0.769 -> 0.857).
    # 34 worlds at 0.2 m (seed 0) and 0.1 m (seeds 0 and 1): no other run changed.
    touch_range_m: float = Field(default=2.0, gt=0.0)
    min_votes: float = Field(default=15.0, gt=0.0)  # a line needs this many echoes ...
    min_places: int = Field(default=3, ge=2)  # ... from this many places (5 cm apart) ...
    min_length_m: float = Field(default=0.15, ge=0.0)  # ... touching it over this length
    tolerance_m: float = Field(default=0.02, gt=0.0)  # an echo supports a line this close to tangent
    clear_m: float = Field(default=0.05, gt=0.0)  # echoes this close to a wall found vote no more
    max_scatter_m: float = Field(default=0.012, gt=0.0)  # rms distance of the supporting echoes
    same_deg: float = Field(default=4.0, ge=0.0)  # lines this close in direction ...
    same_m: float = Field(default=0.1, ge=0.0)  # ... and in distance are one wall
    max_gap_m: float = Field(default=0.25, gt=0.0)  # a stretch without touch points this long splits a wall
    min_spread_ratio: float = Field(default=1.0, ge=0.0)  # the stretch over the range spread
    trim_percent: float = Field(default=5.0, ge=0.0, lt=50.0)  # touch points left off each end
    band_m: float = Field(default=0.05, ge=0.0)  # occupied evidence this close to a line ...
    # ... along this share of it. 0.6 -> 0.5 over 85 worlds x 3 seeds: mean F1 0.9799 -> 0.9802, 22
    # runs up (trapezoid seed 1 +0.010), 6 down (at most -0.005); 64 fresh rooms x 2 seeds 3 up, 2
    # down, +0.0002; at 0.1 m 3 up, none down; 0.7 lost 71 runs, 0.4 and 0.45 added only downs.
    min_on_evidence: float = Field(default=0.5, ge=0.0, le=1.0)
    # A cell is cut when the line passes this far into it. 0.015 -> 0.008 over 85 worlds x 3 seeds:
    # mean F1 0.9785 -> 0.9796, 89 runs up (hexagon seed 1 +0.008), 14 down (at most -0.003); at
    # 0.1 m over 21 worlds x 2 seeds 0.9586 -> 0.9589 (13 up, 6 down); 0.004 added 0.0003 (40 up, 20 down).
    margin_m: float = Field(default=0.008, ge=0.0)
    # Faces along the grid's axes are left to the evidence grid: a face on a cell boundary (rooms
    # are written on a 5 cm step) seen with 2 cm of pose error would cut the free cell beside it.
    min_axis_angle_deg: float = Field(default=3.0, ge=0.0, le=45.0)
    # A wall that far off an axis is still one (a room that is not a box has them along its box
    # edges, where the face band hides them): from near_axis_min_deg it cuts the cells it reaches
    # near_axis_margin_m past, which a wall on a cell boundary seen with 2 cm of pose error and a
    # degree of turn does not. 85 worlds x 3 seeds: 2 runs gained 0.018-0.019, none lost; from 1.0
    # degree, 2 lost (openhall seed 2 -0.027, lhall seed 0 -0.001) and none gained.
    near_axis_min_deg: float = Field(default=1.5, ge=0.0, le=45.0)
    near_axis_margin_m: float = Field(default=0.03, ge=0.0)
    # Echoes seldom touch a wall near a corner (the corner answers first), so a wall's stretch is
    # extended to where it meets another wall found, when that lies within corner_reach_m past the
    # ends of both stretches (or on the other's) and the two meet at corner_min_deg or more.
    corner_reach_m: float = Field(default=0.4, ge=0.0)
    corner_min_deg: float = Field(default=15.0, gt=0.0, le=90.0)
    # ... or meets an edge of the room's surveyed box (when the map size is known): a room that is
    # not a box touches it at vertices, where the walls leaving them stopped short.
    meet_box: bool = True
    # A wall whose stretch ends within box_approach_m of the box edge and runs towards it (from
    # near_axis_min_deg off it) is extended to the edge however far that is: a wall a few degrees
    # off the edge meets it metres away, at a vertex echoes seldom reach. 85 worlds x 3 seeds: 23
    # runs up (by up to 0.015), 2 down (0.005 and 0.0025: walls found 3 degrees off), mean F1
    # 0.9795 -> 0.9799; 0.3 m added 5 up and 2 down.
    box_approach_m: float = Field(default=0.15, ge=0.0)
    # A wall found along a box edge but leaning box_lean_min_deg or more off it is not the box's own
    # (those are found within 1.1 degrees of it) but a wall of a room that is not a box, leaving the
    # edge at a vertex: every map cell along it holds a sliver of wall, however thin, so it cuts the
    # cells it crosses with a margin of box_lean_margin_m, not near_axis_margin_m. 85 worlds x 3
    # seeds at 0.2 m: 10 runs up (polygons, by 0.003-0.013), none down; 96 furnished rooms and the
    # paper rooms unchanged; at 0.1 m (53 worlds) 2 up, 1 down by 0.003. From 1.0 degree a furnished
    # room lost 0.004; margins of 0.4 and 0.8 cm gained less.
    box_lean_min_deg: float = Field(default=1.5, ge=0.0, le=45.0)
    box_lean_margin_m: float = Field(default=0.0, ge=0.0)


def _off(theta: float, axes: NDArray[np.float64]) -> NDArray[np.float64]:
    """How far each of ``axes`` points from direction ``theta`` [rad], in [0, pi]."""
    return np.abs(np.remainder(theta - axes + math.pi, 2 * math.pi) - math.pi)


def _off_many(thetas: NDArray[np.float64], axes: NDArray[np.float64]) -> NDArray[np.float64]:
    """``_off`` for each of ``thetas``: one row per direction."""
    return np.abs(np.remainder(thetas[:, None] - axes[None, :] + math.pi, 2 * math.pi) - math.pi)


def _trimmed_ends(values: NDArray[np.float64], percent: float) -> tuple[float, float]:
    """``np.percentile(values, [percent, 100 - percent])`` with its default (linear) method, the same
    numbers without the overhead, which dominated the search for walls."""
    ordered = np.sort(values)
    n = ordered.size
    ends = []
    for q in (percent / 100.0, (100.0 - percent) / 100.0):
        virtual = (n - 1) * q  # numpy's fractional index for the linear method
        if virtual >= n - 1:
            ends.append(float(ordered[-1]))
            continue
        lo = math.floor(virtual)
        t = virtual - lo
        a, b = float(ordered[lo]), float(ordered[lo + 1])
        ends.append(b - (b - a) * (1.0 - t) if t >= 0.5 else a + (b - a) * t)
    return ends[0], ends[1]


@dataclass(frozen=True)
class Line:
    """Points p with n . p = d, n = (cos theta, sin theta) pointing from the room into the wall;
    touched by echoes over [s0, s1] along t = (-sin theta, cos theta)."""

    theta: float
    d: float
    s0: float
    s1: float
    echoes: int
    scatter: float

    @property
    def off_axis_rad(self) -> float:
        """How far the line runs off the nearest of the grid's axes [rad], in [0, pi / 4]."""
        return abs(math.remainder(self.theta, math.pi / 2))

    def depth(self, xs: NDArray[np.float64], ys: NDArray[np.float64]) -> NDArray[np.float64]:
        """How far points lie past the line into the wall [m] (negative: on the room's side)."""
        return math.cos(self.theta) * xs + math.sin(self.theta) * ys - self.d

    def along(self, x: float, y: float) -> float:
        """Where the point lies along the line (s)."""
        return -math.sin(self.theta) * x + math.cos(self.theta) * y

    def along_many(self, xs: NDArray[np.float64], ys: NDArray[np.float64]) -> NDArray[np.float64]:
        """Where points lie along the line (s)."""
        return -math.sin(self.theta) * xs + math.cos(self.theta) * ys

    def depth_at(self, x: float, y: float) -> float:
        """How far the point (x, y) lies past the line into the wall [m]."""
        return math.cos(self.theta) * x + math.sin(self.theta) * y - self.d

    def point(self, s: float) -> tuple[float, float]:
        """The point on the line at ``s`` along it."""
        c, si = math.cos(self.theta), math.sin(self.theta)
        return self.d * c - s * si, self.d * si + s * c

    def near(self, other: Line, turn_rad: float, distance_m: float) -> bool:
        """Whether ``other`` runs within ``turn_rad`` of this line's direction and within
        ``distance_m`` of it over this line's touched stretch (both ends; at the origin when the
        stretch is unbounded)."""
        if abs(math.remainder(self.theta - other.theta, 2 * math.pi)) > turn_rad:
            return False
        if not (math.isfinite(self.s0) and math.isfinite(self.s1)):
            return abs(self.d - other.d) <= distance_m
        return all(abs(other.depth_at(*self.point(s))) <= distance_m for s in (self.s0, self.s1))

    def corner_reach(self, half: float) -> float:
        """How far the corners of a cell of side ``2 * half`` reach from its centre across the line."""
        return half * (abs(math.cos(self.theta)) + abs(math.sin(self.theta)))

    def cells_past(
        self, xs: NDArray[np.float64], ys: NDArray[np.float64], half: float, margin: float
    ) -> NDArray[np.bool_]:
        """Cells (centres ``xs``, ``ys``, side ``2 * half``) that reach ``margin`` or more past the
        line into the wall, along its touched stretch (widened by half a cell)."""
        along = self.along_many(xs, ys)
        past = self.depth(xs, ys) + self.corner_reach(half) >= margin
        return past & (along >= self.s0 - half) & (along <= self.s1 + half)


def box_walls(extent: tuple[float, float, float, float]) -> list[Line]:
    """The four edges of the room box ``extent`` (min x, min y, max x, max y) as walls, each
    touched along its whole length."""
    min_x, min_y, max_x, max_y = extent
    edges = ((0.0, max_x), (math.pi / 2, max_y), (math.pi, -min_x), (-math.pi / 2, -min_y))
    return [Line(theta, d, -math.inf, math.inf, 0, 0.0) for theta, d in edges]


def meet_at_corners(lines: list[Line], params: TangentParams, walls: Sequence[Line] = ()) -> list[Line]:
    """``lines`` with each stretch extended to where it meets another line, or one of ``walls``
    (known walls that are not extended themselves; see ``TangentParams``), never shortened."""
    reach = params.corner_reach_m
    min_sin = math.sin(math.radians(params.corner_min_deg))
    approach = params.box_approach_m
    min_approach_sin = math.sin(math.radians(params.near_axis_min_deg))
    out = []
    for a in lines:
        s0, s1 = a.s0, a.s1
        for b, known in [*((line, False) for line in lines), *((wall, True) for wall in walls)]:
            if b is a:
                continue
            det = math.sin(b.theta - a.theta)
            if det == 0.0 or abs(det) < (min_approach_sin if known and approach > 0.0 else min_sin):
                continue  # parallel lines never meet (a threshold of 0 is allowed)
            # n_a . p = d_a and n_b . p = d_b
            x = (a.d * math.sin(b.theta) - b.d * math.sin(a.theta)) / det
            y = (b.d * math.cos(a.theta) - a.d * math.cos(b.theta)) / det
            sa, sb = a.along(x, y), b.along(x, y)
            if not b.s0 - reach <= sb <= b.s1 + reach:
                continue
            # How far past each end of the stretch the meeting may lie: a stretch that ends within
            # box_approach_m of a known wall and runs towards it goes on to it, however far.
            far0 = far1 = reach if abs(det) >= min_sin else 0.0
            if known and approach > 0.0:
                if -b.depth_at(*a.point(a.s1)) <= approach:
                    far1 = math.inf
                if -b.depth_at(*a.point(a.s0)) <= approach:
                    far0 = math.inf
            if a.s1 < sa <= a.s1 + far1:
                s1 = max(s1, sa)
            elif a.s0 - far0 <= sa < a.s0:
                s0 = min(s0, sa)
        out.append(a if (s0, s1) == (a.s0, a.s1) else replace(a, s0=s0, s1=s1))
    return out


class TangentLines:
    """Echoes collected over a run, and the straight walls they agree on."""

    def __init__(self, half_beam_rad: float, params: TangentParams) -> None:
        self.params = p = params
        self.half = half_beam_rad
        self._step = math.radians(p.theta_step_deg)
        self.n_theta = max(1, round(2 * math.pi / self._step))
        self._chunks: list[NDArray[np.float64]] = []  # per sweep: rows x, y, axis, range
        self._x = self._y = self._axis = self._r = self._norm = np.zeros(0)
        self._far_chunks: list[NDArray[np.float64]] = []  # the same, past max_range_m to touch_range_m
        self._far = np.zeros((4, 0))

    def add(self, xs: list[float], ys: list[float], axes: list[float], ranges: list[float]) -> None:
        """One sweep's echoes: transducer positions [m], beam axes [rad] and ranges [m]."""
        echoes = np.array([xs, ys, axes, ranges], dtype=np.float64).reshape(4, -1)
        short = echoes[3] <= self.params.max_range_m
        if short.any():
            self._chunks.append(echoes[:, short])
        far = ~short & (echoes[3] <= self.params.touch_range_m)
        if far.any():
            self._far_chunks.append(echoes[:, far])

    def _gather(self) -> int:
        """Join the sweeps' echoes into one array per quantity; returns how many there are."""
        if self._chunks:
            joined = np.concatenate([np.stack([self._x, self._y, self._axis, self._r]), *self._chunks], axis=1)
            self._x, self._y, self._axis, self._r = joined
            self._chunks.clear()
        return int(self._r.size)

    def lines(self) -> list[Line]:
        """The walls the echoes so far agree on, strongest first. Each wall found takes its echoes
        out of the vote before the next is looked for, so one wall is not found again turned by a
        degree about the middle of its echoes."""
        p = self.params
        n = self._gather()
        if n < p.min_votes:
            return []
        # Every echo votes for the normal directions inside its cone (one bin each), at the distance
        # of the line tangent to its circle there, split between the two nearest distance bins.
        span = int(math.floor(self.half / self._step))
        offsets = np.arange(-span, span + 1)
        axis_bin = np.rint(self._axis / self._step).astype(np.int64)
        tb = (axis_bin[:, None] + offsets[None, :]) % self.n_theta  # (echo, vote)
        theta = tb * self._step
        d = np.cos(theta) * self._x[:, None] + np.sin(theta) * self._y[:, None] + self._r[:, None]
        pos = d / p.d_step_m
        lo = np.floor(pos)
        frac = pos - lo
        d0 = float(lo.min())
        n_d = int(lo.max() - d0) + 2
        acc = np.zeros(self.n_theta * n_d)
        base = tb * n_d + (lo - d0).astype(np.int64)
        np.add.at(acc, base.ravel(), (1.0 - frac).ravel())
        np.add.at(acc, (base + 1).ravel(), frac.ravel())
        self._norm = np.hypot(self._x, self._y)  # each transducer place's distance from the origin
        free = np.ones(n, dtype=bool)  # echoes no wall has taken yet
        found: list[Line] = []
        while True:
            peak = int(np.argmax(acc))
            if acc[peak] < p.min_votes:
                return found
            acc[peak] = -np.inf  # tried
            t_i, d_i = divmod(peak, n_d)
            walls = self._refine(t_i * self._step, (d_i + d0) * p.d_step_m, free)
            if not walls:
                continue
            # A line close to a stronger one and nearly parallel is the same wall, seen while the
            # pose was a few centimetres off: it says nothing new, and would cut the floor in front.
            found.extend(w for w in walls if not any(self._same(w, o) for o in found))
            line = walls[0]
            # The echoes near the wall, a little wider than those that fit it: noisier echoes of the
            # same wall would otherwise make a second wall beside it.
            c, s = math.cos(line.theta), math.sin(line.theta)
            dist = c * self._x + s * self._y + self._r
            facing = _off(line.theta, self._axis) <= self.half
            near = free & facing & (np.abs(dist - line.d) <= p.clear_m)
            free &= ~near
            np.subtract.at(acc, base[near].ravel(), (1.0 - frac[near]).ravel())
            np.subtract.at(acc, (base[near] + 1).ravel(), frac[near].ravel())

    def _same(self, a: Line, b: Line) -> bool:
        return a.near(b, math.radians(self.params.same_deg), self.params.same_m)

    def touches(self, line: Line) -> NDArray[np.float64]:
        """Where along ``line`` the echoes tangent to it (within ``tolerance_m``, inside their cone)
        touch it, in increasing order (echoes up to ``touch_range_m``)."""
        along, short = self._against(line)
        far_along, far_short = self._against(line, far=True)
        tol = self.params.tolerance_m
        return np.sort(np.concatenate([along[np.abs(short) <= tol], far_along[np.abs(far_short) <= tol]]))

    def flush_touches(self, line: Line, short_m: float, reach_m: float, max_ratio: float) -> NDArray[np.float64]:
        """``touches(line)`` without the stretches that a wall curving or leaning away from the line
        touched: stretches (split where no echo touched the line for ``max_gap_m``) within
        ``reach_m`` of which the echoes that fell between ``tolerance_m`` and ``short_m`` short of
        the line number ``max_ratio`` of the stretch's touches or more.

        A flat wall on the line is touched from wherever the robot faces it, and echoes fall short
        of it only by their range noise; a curved wall, or one meeting the line at a vertex, is
        touched only where it reaches the line, and echoes from beside that stretch fall a few
        centimetres short.

        The echoes that vote for lines (up to ``max_range_m``) decide this. The longer ones (to
        ``touch_range_m``) are too noisy, and too much affected by a heading error, to tell a flat
        wall by how many fall short: each of their touches counts within ``reach_m`` of a touch
        kept, or where no close echo within ``reach_m`` came within ``short_m`` of the line."""
        along, short = self._against(line)
        tol = self.params.tolerance_m
        touched = np.sort(along[np.abs(short) <= tol])
        near = np.sort(along[(short >= -short_m) & (short <= short_m)])  # what the close echoes saw
        kept = []
        if touched.size:
            fell_short = np.sort(along[(short > tol) & (short <= short_m)])
            for piece in np.split(touched, np.flatnonzero(np.diff(touched) > self.params.max_gap_m) + 1):
                first = np.searchsorted(fell_short, piece[0] - reach_m)
                count = np.searchsorted(fell_short, piece[-1] + reach_m, side="right") - first
                if count < max_ratio * piece.size:
                    kept.append(piece)
        flush = np.concatenate(kept) if kept else touched[:0]
        far_along, far_short = self._against(line, far=True)
        far = np.sort(far_along[np.abs(far_short) <= tol])
        if far.size:
            lo, hi = far - reach_m, far + reach_m
            beside = np.searchsorted(flush, hi, side="right") > np.searchsorted(flush, lo)
            unseen = np.searchsorted(near, hi, side="right") == np.searchsorted(near, lo)
            kept.append(far[beside | unseen])
        return np.sort(np.concatenate(kept)) if kept else touched[:0]

    def _against(self, line: Line, far: bool = False) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """For the echoes whose cone holds ``line``'s normal: where along the line each would touch
        it, and how far short of the line its tangent falls [m] (negative past it). With ``far``,
        the echoes past ``max_range_m`` up to ``touch_range_m`` instead of those that vote."""
        if far:
            if self._far_chunks:
                self._far = np.concatenate([self._far, *self._far_chunks], axis=1)
                self._far_chunks.clear()
            xs, ys, axes, ranges = self._far
        else:
            self._gather()
            xs, ys, axes, ranges = self._x, self._y, self._axis, self._r
        c, s = math.cos(line.theta), math.sin(line.theta)
        facing = _off(line.theta, axes) <= self.half
        x, y, r = xs[facing], ys[facing], ranges[facing]
        return line.along_many(x + r * c, y + r * s), line.d - (c * x + s * y + r)

    def near_box(self, line: Line, extent: tuple[float, float, float, float]) -> bool:
        """Whether ``line`` runs along an edge of the room box (within ``same_deg`` and ``same_m``)."""
        return any(self._same(line, edge) for edge in box_walls(extent))

    def leans(self, line: Line) -> bool:
        """Whether ``line`` runs ``box_lean_min_deg`` or more off the grid's axes."""
        return line.off_axis_rad >= math.radians(self.params.box_lean_min_deg)

    def _best_turn(
        self, theta: float, d: float, free: NDArray[np.bool_]
    ) -> tuple[float, float, NDArray[np.bool_]] | None:
        """The direction within a degree of ``theta``, in tenths, whose line the ``free`` echoes
        near (theta, d) fit best: the direction, the median distance of those echoes from it, and
        the echoes within the tolerance of that distance (None if too few echoes are near)."""
        p = self.params
        turns = np.radians(np.arange(-1.0, 1.01, 0.1))
        # The echoes that can support a line within those turns (an echo's tangent distance moves by
        # at most the turn times its distance from the origin), so the search runs over them alone.
        most = float(np.max(np.abs(turns))) + 1e-9
        reach = most * self._norm
        facing = _off(theta, self._axis) <= self.half + most
        dist0 = math.cos(theta) * self._x + math.sin(theta) * self._y + self._r
        idx = np.flatnonzero(free & facing & (np.abs(dist0 - d) <= 2.0 * p.tolerance_m + reach))
        x, y, axis, r = self._x[idx], self._y[idx], self._axis[idx], self._r[idx]
        # Every turn at once, one row each: the echoes inside the cone, those near the seed line, the
        # median of their distances, and the score of the echoes near that median.
        ths = theta + turns
        inside = _off_many(ths, axis) <= self.half
        dist_all = np.cos(ths)[:, None] * x + np.sin(ths)[:, None] * y + r
        near_all = inside & (np.abs(dist_all - d) <= p.tolerance_m)
        counts = np.count_nonzero(near_all, axis=1)
        rows = np.flatnonzero(counts >= p.min_votes)
        if rows.size == 0:
            return None
        # np.median's numbers: the mean of the middle two of the sorted distances, which for an odd
        # count are the same one (halving a doubled float is exact).
        ordered = np.sort(np.where(near_all[rows], dist_all[rows], np.inf), axis=1)
        k = counts[rows]
        pick = np.arange(rows.size)
        centres = 0.5 * (ordered[pick, (k - 1) // 2] + ordered[pick, k // 2])
        offs = dist_all[rows] - centres[:, None]
        near_rows = inside[rows] & (np.abs(offs) <= p.tolerance_m)
        scores = np.where(near_rows, 1.0 - (offs / p.tolerance_m) ** 2, 0.0).sum(axis=1)
        # Many echoes close to the line: a turned line that keeps only the closest few of them
        # scatters less but is not the wall. The first best turn wins a tie.
        top = int(np.argmax(scores))
        near = np.zeros_like(free)
        near[idx[near_rows[top]]] = True
        return float(ths[rows[top]]), float(centres[top]), near

    def _refine(self, theta: float, d: float, free: NDArray[np.bool_]) -> list[Line]:
        """The line near (theta, d) that the most ``free`` echoes fit, as the stretches of wall
        they touch."""
        p = self.params
        best = self._best_turn(theta, d, free)
        if best is None:
            return []
        th, centre, near = best
        c, s = math.cos(th), math.sin(th)
        dist = c * self._x[near] + s * self._y[near] + self._r[near]
        if float(np.sqrt(np.mean((dist - centre) ** 2))) > p.max_scatter_m:
            return []
        fx = self._x[near] + self._r[near] * c  # where each echo touches the line
        fy = self._y[near] + self._r[near] * s
        along = -s * fx + c * fy
        order = np.argsort(along, kind="stable")
        # A wall with a doorway in it is two walls: split where no echo touched the line for a while.
        pieces = np.split(order, np.flatnonzero(np.diff(along[order]) > p.max_gap_m) + 1)
        idx = np.flatnonzero(near)
        walls = []
        for piece in pieces:
            if piece.size < p.min_votes:
                continue
            sel = idx[piece]
            # The places the echoes came from, on a 5 cm grid (one integer key per grid point).
            keys = np.rint(self._x[sel] / 0.05) * 1e7 + np.rint(self._y[sel] / 0.05)
            if np.unique(keys).size < p.min_places:
                continue
            # Where the wall is: the touch points without the outer few, which near a corner may be
            # the neighbouring wall's echoes that happen to fit. Echoes from places in a row towards
            # one point agree on lines turned a little off the row too, touching them over a stretch
            # that grows with the range they span; a wall seen while driving along it spans a longer
            # stretch than ranges.
            s0, s1 = _trimmed_ends(along[piece], p.trim_percent)
            r0, r1 = _trimmed_ends(self._r[sel], p.trim_percent)
            if s1 - s0 < max(p.min_length_m, p.min_spread_ratio * (r1 - r0)):
                continue
            scatter = float(np.sqrt(np.mean((dist[piece] - centre) ** 2)))
            walls.append(Line(th, centre, s0, s1, int(piece.size), scatter))
        return walls

    def on_evidence(self, line: Line, fine: GridSpec, occupied: NDArray[np.bool_]) -> bool:
        """Whether the evidence grid shows a surface along ``line``: an occupied cell within a few
        centimetres of it along most of its length. A line that echoes agree on by chance (around
        round furniture, or from places in a row) runs mostly through open floor."""
        p = self.params
        c, s = math.cos(line.theta), math.sin(line.theta)
        along = np.arange(line.s0, line.s1 + 1e-9, 0.5 * fine.resolution)
        hits = np.zeros(along.size, dtype=bool)
        for depth in np.arange(-p.band_m, p.band_m + 1e-9, 0.5 * fine.resolution):
            rows, cols = fine.world_to_index((line.d + depth) * c - along * s, (line.d + depth) * s + along * c)
            inside = fine.contains_index(rows, cols)
            hits |= inside & occupied[np.clip(rows, 0, fine.rows - 1), np.clip(cols, 0, fine.cols - 1)]
        return float(np.mean(hits)) >= p.min_on_evidence

    def cut_cells(self, grid: GridSpec, lines: list[Line], margin_m: float | None = None) -> NDArray[np.bool_]:
        """Map cells that a line's touched stretch crosses, reaching at least ``margin_m`` past the
        line into the wall (by default the params' margin for a line at that angle)."""
        out = np.zeros(grid.shape, dtype=bool)
        if not lines:
            return out
        res = grid.resolution
        xs, ys = grid.centers()
        half = 0.5 * res
        for line in lines:
            off_axis = line.off_axis_rad
            margin = self.params.margin_m if margin_m is None else margin_m
            if margin_m is None and off_axis < math.radians(self.params.min_axis_angle_deg):
                if off_axis < math.radians(self.params.near_axis_min_deg):
                    continue
                margin = self.params.near_axis_margin_m
            # Crossed by the line (not wholly past it), and reaching the margin past it.
            crossed = line.depth(xs, ys) - line.corner_reach(half) < 0.0
            out |= crossed & line.cells_past(xs, ys, half, margin)
        return out
