"""Heading fixes from the room's surveyed box: how position fixes drift tells the heading error.

A box fix (``robot.boxfix``) measures the robot's true distance to a box wall, so it measures the
error of the dead-reckoned position along one axis. Odometry integrated with a heading that is off
by a small angle ``delta`` drifts across its direction of travel: the error along x grows by
``-delta`` times the distance travelled along y, the error along y by ``+delta`` times the distance
along x. A wheel scale error ``scale`` adds ``-scale`` times the distance along the same axis. Fixes
collected over a few metres of travel are fitted (least squares, with a prior that keeps the scale
small, and one pass of outlier rejection) to ``error_x = c_x - delta * y - scale * x`` and
``error_y = c_y + delta * x - scale * y``; once ``delta`` is known to a fraction of a degree it goes
into the heading filter as a measurement, and the collection starts again.

Position fixes alone cannot do this: they stop the position from drifting near the walls, but a
heading that is off by two degrees puts a wall seen from the middle of a large room 20 cm off its
place, and lets the position drift past the fixes' gate, after which they stop.

``WallFixes`` applies both to the dead reckoning, sweep by sweep, and also takes a bump into a box
wall as a position fix: the engine and the replay of a log call it alike, so a log replays exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from robot.boxfix import BoxFixConfig, DriftGate, box_offsets, map_shows_edge
from robot.config import RobotConfig
from robot.linefix import LineFixConfig, LineFixes
from robot.localization import DeadReckoning
from robot.mapping.base import Evidence, MapFrame
from robot.mapping.journal import Repair
from robot.world import Pose


class HeadingFixConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = True
    min_fixes: int = Field(default=8, ge=3)  # fixes collected before a fit is tried
    min_spread_m: float = Field(default=1.0, gt=0.0)  # travel the fixes must span across their axis
    # One position fix's error: sonar noise, 1 cm steps and what the model leaves out (a fit's scatter
    # over runs matched its claimed doubt at 3 cm, and was twice that at 1.5 cm).
    fix_std_m: float = Field(default=0.03, gt=0.0)
    scale_prior_std: float = Field(default=0.02, gt=0.0)  # wheel scale error, relative
    # Apply a fit only when delta is this sure. Over 4-6 seeds of 13 worlds, 0.3 degrees gave noisier
    # corrections; applying only fits that are clearly not zero (|delta| > 2 std) helped two small
    # rooms by 0.001-0.003 of F1 and cost a long room 0.025.
    max_std_deg: float = Field(default=0.2, gt=0.0)
    outlier_sigma: float = Field(default=3.0, gt=0.0)
    max_fixes: int = Field(default=400, ge=3)  # the oldest fixes are dropped beyond this


@dataclass(frozen=True)
class HeadingFit:
    delta_rad: float  # heading error: true minus estimated [rad]
    std_rad: float
    fixes: int


class WallHeading:
    """Collects position fixes against the box and, when they say enough, the heading error."""

    def __init__(self, config: HeadingFixConfig) -> None:
        self.config = config
        # One row per fix: axis (0 = x, 1 = y), measured error (true - odometry) [m], odometry x, y [m].
        self._rows: list[tuple[int, float, float, float]] = []

    def add(self, axis: int, error_m: float, odo_x: float, odo_y: float) -> None:
        """A position fix: along ``axis``, the true position minus the odometry-only position."""
        self._rows.append((axis, error_m, odo_x, odo_y))
        if len(self._rows) > self.config.max_fixes:
            del self._rows[0]

    def reset(self) -> None:
        """Forget the fixes (the heading has just been corrected: the odometry before it is off)."""
        self._rows.clear()

    def fit(self) -> HeadingFit | None:
        """The heading error, if the fixes so far pin it down well enough; else None."""
        cfg = self.config
        if len(self._rows) < cfg.min_fixes:
            return None
        rows = np.array(self._rows, dtype=np.float64)
        axis, err, ox, oy = rows.T
        is_x = axis == 0
        # Spread of travel across each axis: what makes delta observable.
        across = np.where(is_x, oy, ox)
        spread = max(
            (float(np.ptp(across[sel])) for sel in (is_x, ~is_x) if np.count_nonzero(sel) >= 2),
            default=0.0,
        )
        if spread < cfg.min_spread_m:
            return None
        keep = np.ones(len(rows), dtype=bool)
        for _ in range(2):
            solved = self._solve(is_x[keep], err[keep], ox[keep], oy[keep])
            if solved is None:
                return None
            params, cov = solved
            resid = err - self._design(is_x, ox, oy) @ params
            inliers = np.abs(resid) <= cfg.outlier_sigma * cfg.fix_std_m
            if np.array_equal(inliers, keep):
                break
            keep = inliers
            if np.count_nonzero(keep) < cfg.min_fixes:
                return None
        delta, std = float(params[2]), math.sqrt(max(float(cov[2, 2]), 0.0))
        if std > math.radians(cfg.max_std_deg):
            return None
        return HeadingFit(delta, std, int(np.count_nonzero(keep)))

    @staticmethod
    def _design(is_x: np.ndarray, ox: np.ndarray, oy: np.ndarray) -> np.ndarray:
        """Columns: c_x, c_y, delta, scale."""
        a = np.zeros((len(is_x), 4))
        a[:, 0] = is_x
        a[:, 1] = ~is_x
        a[:, 2] = np.where(is_x, -oy, ox)
        a[:, 3] = np.where(is_x, -ox, -oy)
        return a

    def _solve(
        self, is_x: np.ndarray, err: np.ndarray, ox: np.ndarray, oy: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        cfg = self.config
        a = self._design(is_x, ox, oy) / cfg.fix_std_m
        b = err / cfg.fix_std_m
        # The scale's prior (zero), and a loose one (1 m) on each offset so that an axis without
        # fixes leaves the system solvable: fixes along one wall alone still measure the heading.
        prior = np.diag([1.0, 1.0, 0.0, 1.0 / cfg.scale_prior_std])
        a = np.vstack([a, prior])
        b = np.concatenate([b, np.zeros(4)])
        normal = a.T @ a
        if np.linalg.cond(normal) > 1e12:
            return None
        cov = np.linalg.inv(normal)
        return cov @ a.T @ b, cov


def repairs_possible(frame: MapFrame, box: BoxFixConfig) -> bool:
    """Whether ``WallFixes`` can ask for the map to be repaired (see ``BoxFixConfig.drift_repair``)."""
    return frame.extent is not None and box.enabled and box.drift_repair and box.gate_growth > 0.0


class WallFixes:
    """Position and heading fixes from one sweep's echoes off the room box, and position fixes off
    the walls the robot mapped itself (``robot.linefix``: in a room of unknown size, or when asked
    for), applied to the dead reckoning; the engine and the replay of a log call it alike."""

    def __init__(
        self,
        frame: MapFrame,
        robot: RobotConfig,
        box: BoxFixConfig,
        heading: HeadingFixConfig,
        line: LineFixConfig | None = None,
    ) -> None:
        self.frame = frame
        self.robot = robot
        self.box = box
        self.heading = WallHeading(heading) if heading.enabled and box.enabled and frame.extent is not None else None
        self.heading_fixes: list[HeadingFit] = []
        self.contact_fixes = 0
        self.gate = DriftGate(box)
        self._fixed_at = [0.0, 0.0]  # the odometer at each axis's last fix within the fixed gate [m]
        self._repairs: list[Repair] = []
        self._trusted: list[Evidence | None] = [None, None]  # the map at each axis's last fix within the gate
        known = frame.extent is not None
        self.lines: LineFixes | None = None
        if line is not None and line.enabled and (line.with_known_box or not known):
            self.lines = LineFixes(robot, line, box_known=known)
        self._box_idle = [0, 0]  # sweeps since each axis's last box fix

    def apply(self, dr: DeadReckoning, pose: Pose, ranges_m: NDArray[np.float64], evidence: Evidence | None) -> Pose:
        """The pose after this sweep's fixes (``pose`` itself when there are none): the box's, then
        the landmark walls' (``robot.linefix``)."""
        pose = self._apply_box(dr, pose, ranges_m, evidence)
        if self.lines is not None:
            shift = self.lines.offset(pose, ranges_m)
            if shift is not None:
                est = dr.shift_position(*shift)
                self.gate.follow(est.x, est.y, drove=False)
                pose = est.as_pose()
            self.lines.observe(pose, ranges_m, max(self._box_idle))
        return pose

    def _apply_box(
        self, dr: DeadReckoning, pose: Pose, ranges_m: NDArray[np.float64], evidence: Evidence | None
    ) -> Pose:
        self.gate.follow(pose.x, pose.y, theta_std=dr.estimate.theta_std)
        ox, oy = box_offsets(
            self.frame, self.robot, pose, ranges_m, self.box, evidence, self.gate, (self._trusted[0], self._trusted[1])
        )
        self._box_idle = [0 if o is not None else n + 1 for o, n in zip((ox, oy), self._box_idle, strict=True)]
        if ox is None and oy is None:
            return pose
        shift = [0.0, 0.0]
        for axis, offset in enumerate((ox, oy)):
            if offset is None:
                continue
            if abs(offset) <= self.box.gate_m:
                self._fixed_at[axis] = dr.distance_m
                self._trusted[axis] = evidence
            elif self.box.drift_repair:
                # Readings along the wall agree that the estimate has drifted: correct it at once,
                # and the map with it.
                self._repairs.append(Repair(axis, offset, self._fixed_at[axis], dr.distance_m))
                self._fixed_at[axis] = dr.distance_m
                shift[axis] = offset
                self.gate.fixed(axis, 0.0)
                continue
            shift[axis] = self.box.gain * offset
            self.gate.fixed(axis, offset * (1.0 - self.box.gain))
        if self.heading is not None:
            odo_x, odo_y = dr.odometry_xy
            if ox is not None:
                self.heading.add(0, ox + pose.x - odo_x, odo_x, odo_y)
            if oy is not None:
                self.heading.add(1, oy + pose.y - odo_y, odo_x, odo_y)
        est = dr.shift_position(shift[0], shift[1])
        self.gate.follow(est.x, est.y, drove=False)
        if self.heading is not None and (fit := self.heading.fit()) is not None:
            est = dr.correct_heading(fit.delta_rad, fit.std_rad)
            self.heading.reset()
            self.heading_fixes.append(fit)
        return est.as_pose()

    def take_repairs(self) -> list[Repair]:
        """The corrections that the map needs after the last sweep's fixes, once (see
        ``BoxFixConfig.drift_repair``)."""
        repairs, self._repairs = self._repairs, []
        return repairs

    def contact(
        self, dr: DeadReckoning, pose: Pose, direction_rad: float, evidence: Evidence | None
    ) -> tuple[Pose, bool]:
        """A bump while driving along ``direction_rad``. When the body would touch a box wall ahead
        within ``contact_gate_m`` of where the estimate puts it, and within the drift that the
        distance driven since that axis's last fix allows (``DriftGate``, plus ``contact_spare_m``),
        and the map shows that edge as a wall there and along a stretch of it (in a room that is not
        a rectangle an angled wall may meet the box edge), the bump was that wall: it fixes the
        position across the wall, and needs no contact evidence. Returns the pose and whether the
        bump should still be marked on the map."""
        gate = self.box.contact_gate_m
        if self.frame.extent is None or not self.box.enabled or gate <= 0.0:
            return pose, True
        min_x, min_y, max_x, max_y = self.frame.extent
        radius = self.robot.radius_m
        along = (math.cos(direction_rad), math.sin(direction_rad))
        head_on = math.cos(math.radians(self.box.contact_max_angle_deg))
        half = max(2 * radius, self.box.contact_support_m)  # how far along the edge the map must show it
        best: tuple[float, int, float] | None = None  # |offset|, axis, offset
        for axis, sign, edge in ((0, 1.0, max_x), (0, -1.0, min_x), (1, 1.0, max_y), (1, -1.0, min_y)):
            if sign * along[axis] < head_on:
                continue
            offset = (edge - sign * radius) - (pose.x, pose.y)[axis]  # the body touching the wall
            drift = self.gate.limit(axis) + self.box.contact_spare_m
            if abs(offset) > min(gate, drift) or (best is not None and abs(offset) >= best[0]):
                continue
            hit = (edge, pose.y) if axis == 0 else (pose.x, edge)
            span = (min_y, max_y) if axis == 0 else (min_x, max_x)
            # The edge solid along the body's support, and the wall on the edge along a stretch, not a
            # wall slanting into it at a vertex.
            if evidence is None or not map_shows_edge(evidence, hit, axis == 0, sign, half, self.box, span, True):
                continue
            best = (abs(offset), axis, offset)
        if best is None:
            return pose, True
        _, axis, offset = best
        est = dr.shift_position(offset if axis == 0 else 0.0, offset if axis == 1 else 0.0)
        self.gate.fixed(axis, 0.0)
        self._fixed_at[axis] = dr.distance_m
        self.gate.follow(est.x, est.y, drove=False)
        self.contact_fixes += 1
        return est.as_pose(), False
