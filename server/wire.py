"""The live protocol's wire forms (docs/protocol.md): integer units, and steps that carry only what changed."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

PROTOCOL_VERSION = 2
MILLI = 1000  # positions go as integer millimetres, angles as integer milliradians
CENTI = 100  # sonar ranges go as integer centimetres (the SRF02's own resolution)

# What a step may say besides its type, seq, cells and merged count, with the values a run starts from.
# A step carries one of these only when its value differs from the step before (the snapshot has them
# all), so a viewer that applied every step since its snapshot always holds the latest of each.
VIEW_FIELDS: dict[str, Any] = {
    "t_s": 0.0,  # simulated (or hardware) clock at the end of the step [s]
    "pose": None,  # [x mm, y mm, theta mrad]
    "sweep": None,  # ranges in mounting order [cm]
    "target": None,  # [x mm, y mm]
    "action": None,
    "explored": None,  # share of the truly reachable area mapped free
    "frontier": None,  # frontier cells
    "metrics": None,  # live scores against the truth
}


def milli(value: float) -> int | None:
    return round(value * MILLI) if math.isfinite(value) else None


def pose_wire(x_m: float, y_m: float, theta_rad: float) -> list[int | None]:
    return [milli(x_m), milli(y_m), milli(theta_rad)]


def point_wire(x_m: float, y_m: float) -> list[int | None]:
    return [milli(x_m), milli(y_m)]


def sweep_wire(ranges_m: Sequence[float] | np.ndarray, max_range_m: float | None) -> list[int | None]:
    """Ranges in centimetres; an echo just short of the maximum range stays short of it, so that the
    maximum still means "no echo" alone."""
    ranges = np.asarray(ranges_m, dtype=np.float64)
    cm = np.rint(ranges * CENTI)
    if max_range_m is not None:
        cm = np.where(ranges < max_range_m, np.minimum(cm, round(max_range_m * CENTI) - 1), cm)
    return [int(v) if math.isfinite(v) else None for v in cm.tolist()]


def _metres(values: Sequence[float | None]) -> list[float]:
    return [math.nan if v is None else float(v) for v in values]  # a checkpoint writes null for NaN


def trail_wire(points_m: Iterable[Sequence[float | None]]) -> list[list[int | None]]:
    return [point_wire(*_metres(p)) for p in points_m]


def view_from_checkpoint(saved: dict[str, Any], max_range_m: float | None) -> dict[str, Any]:
    """The wire view of a checkpoint's ``state.json`` (which keeps metres and radians)."""
    view = dict(VIEW_FIELDS)
    pose = saved.get("pose")
    if isinstance(pose, dict):
        view["pose"] = pose_wire(*_metres([pose.get("x"), pose.get("y"), pose.get("theta")]))
    if saved.get("sweep") is not None:
        view["sweep"] = sweep_wire(_metres(saved["sweep"]), max_range_m)
    if saved.get("target") is not None:
        view["target"] = point_wire(*_metres(saved["target"]))
    progress = saved.get("progress") or {}
    view["step"] = int(progress.get("step") or 0)
    view["t_s"] = progress.get("sim_time_s") or 0.0
    view["explored"] = progress.get("explored")
    view["frontier"] = progress.get("frontier")
    view["action"] = saved.get("action")
    view["metrics"] = saved.get("metrics")
    return view


class StepDeltas:
    """The run body's half of the protocol: each step says what changed since the step before."""

    def __init__(self) -> None:
        self.last = dict(VIEW_FIELDS)

    def message(self, seq: int, step: int, values: dict[str, Any], cells: list[list[int]]) -> dict[str, Any]:
        msg: dict[str, Any] = {"type": "step", "seq": seq}
        if step != seq:
            msg["step"] = step
        for key, value in values.items():
            if value != self.last[key]:
                msg[key] = self.last[key] = value
        if cells:
            msg["cells"] = cells
        return msg


def apply_step(view: dict[str, Any], msg: dict[str, Any]) -> None:
    """Fold a step (or a merged one) into a view: what a viewer does with everything but the cells."""
    for key in VIEW_FIELDS.keys() & msg.keys():
        view[key] = msg[key]
    view["step"] = msg.get("step", msg["seq"])
