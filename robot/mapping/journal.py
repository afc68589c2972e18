"""A mapper that keeps what it was given, so that the map can be rebuilt at corrected poses.

Once a position fix shows that the estimate had drifted (a fix past the fixed gate, see
``robot.boxfix.DriftGate``), the walls mapped while it drifted lie where the drifted estimate put
them, and the evidence they left keeps them there: a strip of false black cells along a wall, a
face missed by a row of cells. Drift grows with the distance driven, so the correction is spread
over what was recorded since the axis's last fix in proportion to the distance driven since then,
and the map is rebuilt from every record at the corrected poses.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from robot.mapping.base import Evidence, MapFrame, Mapper
from robot.world import Pose


@dataclass(frozen=True)
class Repair:
    """The estimate was ``offset_m`` off along ``axis`` (0: x, 1: y; true minus estimated) when the
    odometer read ``to_m``, and right when it read ``from_m``; in between the error grew with the
    distance driven."""

    axis: int
    offset_m: float
    from_m: float
    to_m: float

    def shift(self, odometer_m: float) -> float:
        """The correction [m] for a pose recorded when the odometer read ``odometer_m``."""
        if odometer_m <= self.from_m:
            return 0.0
        if odometer_m >= self.to_m:
            return self.offset_m
        return self.offset_m * (odometer_m - self.from_m) / (self.to_m - self.from_m)


class _Record(NamedTuple):
    odometer_m: float
    pose: Pose
    ranges_m: NDArray[np.float64] | None  # a sweep
    contact_rad: float | None  # a bump, driving towards this direction; neither: the body


class JournaledMapper:
    """A mapper (built by ``build``) whose inputs are kept with the odometer reading at the time
    (``odometer``: metres driven), so that ``repair`` can rebuild it at corrected poses. With
    ``keep`` False (no repair can come: an unknown room, or box fixes off) nothing is kept."""

    def __init__(self, build: Callable[[], Mapper], odometer: Callable[[], float], keep: bool = True) -> None:
        self._build = build
        self._odometer = odometer
        self.keep = keep
        self.inner = build()
        self.name = self.inner.name
        self.frame: MapFrame = self.inner.frame
        self._records: list[_Record] = []
        self.repairs = 0

    def integrate(self, pose: Pose, ranges_m: NDArray[np.float64]) -> None:
        if self.keep:
            self._records.append(_Record(self._odometer(), pose, np.array(ranges_m, dtype=float), None))
        self.inner.integrate(pose, ranges_m)

    def mark_body(self, pose: Pose) -> None:
        if self.keep:
            self._records.append(_Record(self._odometer(), pose, None, None))
        self.inner.mark_body(pose)

    def mark_contact(self, pose: Pose, direction_rad: float) -> None:
        if self.keep:
            self._records.append(_Record(self._odometer(), pose, None, direction_rad))
        self.inner.mark_contact(pose, direction_rad)

    def repair(self, repairs: Sequence[Repair]) -> None:
        """Correct the recorded poses by ``repairs`` and rebuild the map from every record."""
        if not repairs:
            return
        if not self.keep:
            raise RuntimeError("this mapper keeps no records to repair")
        moved = []
        for rec in self._records:
            dx = sum(r.shift(rec.odometer_m) for r in repairs if r.axis == 0)
            dy = sum(r.shift(rec.odometer_m) for r in repairs if r.axis == 1)
            if dx != 0.0 or dy != 0.0:
                rec = rec._replace(pose=Pose(rec.pose.x + dx, rec.pose.y + dy, rec.pose.theta))
            moved.append(rec)
        self._records = moved
        inner = self._build()
        for rec in moved:
            if rec.ranges_m is not None:
                inner.integrate(rec.pose, rec.ranges_m)
            elif rec.contact_rad is not None:
                inner.mark_contact(rec.pose, rec.contact_rad)
            else:
                inner.mark_body(rec.pose)
        self.inner = inner
        self.repairs += 1

    def finalize(self) -> None:
        self.inner.finalize()

    def free_fraction(self) -> NDArray[np.float64]:
        return self.inner.free_fraction()

    def states(self) -> NDArray[np.int8]:
        return self.inner.states()

    def evidence(self) -> Evidence | None:
        return self.inner.evidence()
