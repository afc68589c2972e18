"""Replaying recorded logs into a map: the project's sensors.log and the Udacity 8-sonar text logs.

A project log is replayed exactly as the engine lived it (dead reckoning, tick-hook body marks,
sweeps, contacts), so it rebuilds the engine's map cell for cell. A Udacity log (``measurement.txt``
+ ``poses.txt``) is mapped at its wheel-odometry poses in the odometry frame, on a grid sized from
the trajectory, and exported cropped to what was seen.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ValidationError

from robot.config import CONFIG_DIR, RobotConfig, format_validation_error
from robot.engine import classify
from robot.errors import ConfigError, LogFormatError
from robot.grid import FREE, OCCUPIED, UNKNOWN, GridSpec, cells_to_cover
from robot.hardware import EncoderCounts, ImuSample
from robot.headingfix import WallFixes, repairs_possible
from robot.localization import DeadReckoning
from robot.mapio import atomic_write_bytes, write_map_files
from robot.mapping import Mapper, make_mapper
from robot.mapping.base import MapFrame
from robot.mapping.journal import JournaledMapper
from robot.sensorlog import read_sensor_log
from robot.settings import load_run_config
from robot.slam_config import SlamConfig, slam_config_from_dict
from robot.world import Pose

UDACITY_CONFIG = CONFIG_DIR / "udacity_8sonar.toml"
SENSOR_LOG_NAME = "sensors.log"
UDACITY_FILES = ("measurement.txt", "poses.txt")
BODY_MARK_STEP_M = 0.03  # the engine's tick hook marks the body after this much travel
CLOCK_STARTS_WITH_RUN_S = 60.0  # a log whose first record is later than this has a free-running clock


@dataclass
class ReplayResult:
    """A replayed log: the mapper as the log left it and the sweep poses it used."""

    log: Path
    kind: str  # "sonarslam" (a sensors.log) or "udacity"
    frame: MapFrame
    mapper: Mapper
    slam: SlamConfig
    sweep_poses: NDArray[np.float64]  # (n, 4): t [s], x [m], y [m], theta [rad] of every sweep
    steps: int  # pose updates: E or P records, or Udacity rows
    log_duration_s: float
    wall_time_s: float
    ignored_settings: list[str] = field(default_factory=list)  # header settings this version lacks

    @property
    def sweeps(self) -> int:
        return int(self.sweep_poses.shape[0])

    def states(self) -> NDArray[np.int8]:
        """The exported black / white / grey map over the whole frame, as the engine exports it."""
        return classify(self.mapper.states(), self.frame.start_cell)

    def exported(self) -> tuple[NDArray[np.int8], GridSpec]:
        """The map to write: a Udacity map is cropped to what was seen; a project log's is not,
        so that it matches the engine's map file cell for cell."""
        states = self.states()
        if self.kind == "udacity":
            return crop_to_seen(states, self.frame.grid)
        return states, self.frame.grid


# -- shared pieces ------------------------------------------------------------------------------
def crop_to_seen(states: NDArray[np.int8], grid: GridSpec) -> tuple[NDArray[np.int8], GridSpec]:
    """Drop all-grey border rows and columns; the returned grid's origin keeps every cell in place."""
    seen = states != UNKNOWN
    rows = np.flatnonzero(seen.any(axis=1))
    cols = np.flatnonzero(seen.any(axis=0))
    if rows.size == 0:
        return states, grid
    r0, r1, c0, c1 = int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])
    cropped = GridSpec(
        origin_x=round(grid.origin_x + c0 * grid.resolution, 9),
        origin_y=round(grid.origin_y + (grid.rows - 1 - r1) * grid.resolution, 9),  # row 0 is the top
        resolution=grid.resolution,
        rows=r1 - r0 + 1,
        cols=c1 - c0 + 1,
    )
    return states[r0 : r1 + 1, c0 : c1 + 1].copy(), cropped


class _BodyMarker:
    """The engine's tick hook: mark the body whenever the estimate has moved 3 cm since the last mark."""

    def __init__(self, mapper: Mapper, start: Pose) -> None:
        self.mapper = mapper
        self.last_xy = (start.x, start.y)

    def tick(self, pose: Pose) -> None:
        if math.hypot(pose.x - self.last_xy[0], pose.y - self.last_xy[1]) >= BODY_MARK_STEP_M:
            self.mapper.mark_body(pose)
            self.last_xy = (pose.x, pose.y)


# -- the project's sensor log -----------------------------------------------------------------------
def _header_robot(meta: dict[str, Any], where: str) -> RobotConfig:
    try:
        return RobotConfig.model_validate({**meta["robot"], "sonar": meta["sonar"], "sonars": meta["sonars"]})
    except KeyError as exc:
        raise LogFormatError(f"{where}: header has no {exc.args[0]!r}") from None
    except (TypeError, ValidationError) as exc:
        detail = format_validation_error("header", exc) if isinstance(exc, ValidationError) else str(exc)
        raise LogFormatError(f"{where}: bad robot description: {detail}") from None


def _header_frame(meta: dict[str, Any], where: str, resolution: float | None) -> MapFrame:
    try:
        f = meta["frame"]
        grid = GridSpec(
            float(f["origin"][0]), float(f["origin"][1]), float(f["resolution"]), int(f["rows"]), int(f["cols"])
        )
        start = Pose(*(float(v) for v in f["start"]))
        extent: tuple[float, float, float, float] | None = None
        if f.get("extent") is not None:
            min_x, min_y, max_x, max_y = (float(v) for v in f["extent"])
            extent = (min_x, min_y, max_x, max_y)
    except KeyError as exc:
        raise LogFormatError(f"{where}: header frame has no {exc.args[0]!r}") from None
    except (TypeError, ValueError, IndexError) as exc:
        raise LogFormatError(f"{where}: bad header frame: {exc}") from None
    if grid.rows < 1 or grid.cols < 1 or not grid.resolution > 0:
        raise LogFormatError(f"{where}: bad header frame: {f}")
    if resolution is not None and not math.isclose(resolution, grid.resolution):
        if extent is not None:  # as frame_for_world: the room box at the new resolution
            grid = GridSpec.covering(*extent, resolution)
        else:  # the same area from the same origin
            grid = GridSpec(
                grid.origin_x,
                grid.origin_y,
                resolution,
                cells_to_cover(grid.height_m, resolution),
                cells_to_cover(grid.width_m, resolution),
            )
    return MapFrame(grid=grid, start=start, extent=extent)


def _known_settings(
    data: dict[str, Any], model: type[BaseModel], dropped: list[str], prefix: str = ""
) -> dict[str, Any]:
    """The part of ``data`` that ``model`` still has fields for (the rest is named in ``dropped``):
    a log written by an older version may carry settings that have since been renamed or removed."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        info = model.model_fields.get(key)
        if info is None:
            dropped.append(prefix + key)
            continue
        sub = info.annotation
        if isinstance(value, dict) and isinstance(sub, type) and issubclass(sub, BaseModel):
            value = _known_settings(value, sub, dropped, f"{prefix}{key}.")
        out[key] = value
    return out


def _sensor_log_slam(
    meta: dict[str, Any], where: str, config: Path | str | None, resolution: float | None, dropped: list[str]
) -> SlamConfig:
    """``--config`` if given; else the settings the run recorded in its header; else the defaults."""
    if config is None and isinstance(meta.get("slam"), dict):
        data = _known_settings(meta["slam"], SlamConfig, dropped)
        if resolution is not None:
            data["resolution"] = resolution
        try:
            return slam_config_from_dict(data, f"{where}: header slam settings")
        except ConfigError as exc:
            raise LogFormatError(str(exc)) from None
    return load_run_config(config, {"resolution": resolution}).slam


def replay_sensor_log(
    path: Path | str, config: Path | str | None = None, resolution: float | None = None
) -> ReplayResult:
    """Rebuild the engine's map from a ``sensors.log``: same dead reckoning, same mapper calls, same order."""
    wall0 = time.perf_counter()
    path = Path(path)
    meta, records = read_sensor_log(path)
    where = f"{path}: line 1"
    robot = _header_robot(meta, where)
    dropped: list[str] = []
    slam = _sensor_log_slam(meta, where, config, resolution, dropped)
    frame = _header_frame(meta, where, slam.resolution)
    slam.check_robot(robot)
    first = next(records, None)
    records = itertools.chain([first] if first is not None else [], records)
    dr = DeadReckoning(robot, frame.start, slam.localization)
    fixes = WallFixes(frame, robot, slam.box_fix, slam.heading_fix, slam.line_fix)
    mapper = JournaledMapper(
        lambda: make_mapper(slam.mapper, frame, robot, slam),
        lambda: dr.distance_m,
        keep=repairs_possible(frame, slam.box_fix),
    )
    # Logs record where the encoders start (an O record); for older logs without one, the counts
    # are cumulative since start-up, so zero, taken at the clock's zero when the clock starts with
    # the run (the simulator's does), else at the first record.
    t_origin = 0.0 if first is None or first.t_s <= CLOCK_STARTS_WITH_RUN_S else first.t_s
    dr.reset_origin(EncoderCounts(t_origin, 0, 0))
    n_sonars = len(robot.sonars)
    mapper.mark_body(frame.start)  # the engine's first act
    body = _BodyMarker(mapper, frame.start)
    pose = frame.start
    imu: list[ImuSample] = []
    sweeps: list[tuple[float, float, float, float]] = []
    steps = 0
    t_first: float | None = None
    t_last = 0.0
    for rec in records:
        t_first = rec.t_s if t_first is None else t_first
        t_last = rec.t_s
        if rec.kind == "I":
            imu.append(ImuSample(rec.t_s, rec.values[0]))
        elif rec.kind == "E":
            left, right, driving = rec.values
            pose = dr.update(
                EncoderCounts(rec.t_s, int(left), int(right)), imu, wheels_commanded=bool(driving)
            ).as_pose()
            imu = []
            steps += 1
            body.tick(pose)
        elif rec.kind == "P":
            pose = Pose(*rec.values)
            steps += 1
            body.tick(pose)
        elif rec.kind == "S":
            if len(rec.values) != n_sonars:
                raise LogFormatError(
                    f"{path}: sweep at t={rec.t_s:.4f} s has {len(rec.values)} ranges; "
                    f"the header lists {n_sonars} sonars"
                )
            pose = fixes.apply(dr, pose, rec.ranges, mapper.evidence())  # as the engine does
            mapper.repair(fixes.take_repairs())
            mapper.integrate(pose, rec.ranges)
            mapper.mark_body(pose)
            sweeps.append((rec.t_s, pose.x, pose.y, pose.theta))
        elif rec.kind == "B":
            pose, unexplained = fixes.contact(dr, pose, rec.values[0], mapper.evidence())  # as the engine does
            if unexplained:
                mapper.mark_contact(pose, rec.values[0])
        elif rec.kind == "O":
            dr.reset_origin(EncoderCounts(rec.t_s, int(rec.values[0]), int(rec.values[1])))
    mapper.finalize()  # as the engine does when the run ends
    return ReplayResult(
        log=path,
        kind="sonarslam",
        frame=frame,
        mapper=mapper,
        slam=slam,
        sweep_poses=np.array(sweeps, dtype=float).reshape(-1, 4),
        steps=steps,
        log_duration_s=t_last - (t_first if t_first is not None else t_last),
        wall_time_s=time.perf_counter() - wall0,
        ignored_settings=dropped,
    )


# -- Udacity logs ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class UdacityLog:
    """A Udacity RoboND log in SI units: one sweep per row, at the row's odometry pose."""

    directory: Path
    t_s: NDArray[np.float64]  # (n,) [s]
    poses: NDArray[np.float64]  # (n, 3): x [m], y [m], theta [rad], odometry frame
    ranges_m: NDArray[np.float64]  # (n, sonars) [m]


def _read_int_table(path: Path, columns: int | None) -> NDArray[np.int64]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise LogFormatError(f"{path}: not a text file") from None
    rows: list[list[int]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields:
            continue
        try:
            values = [int(v) for v in fields]
        except ValueError:
            raise LogFormatError(f"{path}: line {lineno}: expected whole numbers, got {line.strip()[:60]!r}") from None
        width = columns if columns is not None else (len(rows[0]) if rows else len(values))
        if len(values) != width:
            raise LogFormatError(f"{path}: line {lineno}: {len(values)} fields, expected {width}")
        rows.append(values)
    if not rows:
        raise LogFormatError(f"{path}: no data rows")
    return np.array(rows, dtype=np.int64)


def read_udacity_log(directory: Path | str) -> UdacityLog:
    """Read ``measurement.txt`` (t_ms r1..rn in mm) and ``poses.txt`` (t_ms x_mm y_mm theta_decideg)."""
    d = Path(directory)
    meas = _read_int_table(d / "measurement.txt", None)
    poses = _read_int_table(d / "poses.txt", 4)
    if meas.shape[1] < 2:
        raise LogFormatError(f"{d / 'measurement.txt'}: line 1: expected a time and at least one range")
    for i in range(min(len(meas), len(poses))):
        if meas[i, 0] != poses[i, 0]:
            raise LogFormatError(
                f"{d / 'poses.txt'}: data row {i + 1}: time {poses[i, 0]} ms does not match "
                f"measurement.txt row {i + 1} ({meas[i, 0]} ms)"
            )
    if len(meas) != len(poses):
        shorter = "poses.txt" if len(poses) < len(meas) else "measurement.txt"
        raise LogFormatError(
            f"{d / shorter}: line {min(len(meas), len(poses)) + 1}: ends early "
            f"({len(meas)} measurement rows, {len(poses)} pose rows)"
        )
    return UdacityLog(
        directory=d,
        t_s=meas[:, 0] / 1000.0,
        poses=np.column_stack([poses[:, 1] / 1000.0, poses[:, 2] / 1000.0, np.radians(poses[:, 3] / 10.0)]),
        ranges_m=meas[:, 1:] / 1000.0,
    )


def frame_for_trajectory(poses: NDArray[np.float64], resolution: float, margin_m: float) -> MapFrame:
    """An unknown room around a known path: the path's bounding box plus ``margin_m``, with the origin
    on a whole multiple of the resolution so that cell edges fall on round odometry coordinates."""
    lo = np.floor((poses[:, :2].min(axis=0) - margin_m) / resolution)
    lo_x, lo_y = (round(float(v) * resolution, 9) for v in lo)  # round: -2 * 0.1 is -0.2, not -0.20000000000000004
    hi = poses[:, :2].max(axis=0) + margin_m
    grid = GridSpec.covering(lo_x, lo_y, float(hi[0]), float(hi[1]), resolution)
    start = Pose(float(poses[0, 0]), float(poses[0, 1]), float(poses[0, 2]))
    return MapFrame(grid=grid, start=start, extent=None)


def replay_udacity(
    log: UdacityLog, robot: RobotConfig, slam: SlamConfig, use_sweep: NDArray[np.bool_] | None = None
) -> ReplayResult:
    """Map a Udacity log at its odometry poses, marking the body as the engine does.

    ``use_sweep`` (one flag per row) leaves some sweeps out, e.g. to test the map on them.
    """
    wall0 = time.perf_counter()
    if log.ranges_m.shape[1] != len(robot.sonars):
        raise LogFormatError(
            f"{log.directory / 'measurement.txt'}: line 1: {log.ranges_m.shape[1]} ranges per row, "
            f"but the config describes {len(robot.sonars)} sonars"
        )
    frame = frame_for_trajectory(log.poses, slam.resolution, robot.sonar.max_range_m + slam.resolution)
    slam.check_robot(robot)
    mapper = make_mapper(slam.mapper, frame, robot, slam)
    mapper.mark_body(frame.start)
    body = _BodyMarker(mapper, frame.start)
    use = np.ones(len(log.t_s), dtype=bool) if use_sweep is None else np.asarray(use_sweep, dtype=bool)
    prev = log.poses[0]
    for i, (x, y, theta) in enumerate(log.poses):
        # Odometry comes at about 5 Hz; the engine's tick hook would have marked the body along the way.
        steps = max(1, math.ceil(math.hypot(x - prev[0], y - prev[1]) / BODY_MARK_STEP_M))
        dtheta = math.remainder(theta - prev[2], 2 * math.pi)
        for f in np.arange(1, steps + 1) / steps:
            body.tick(Pose(prev[0] + f * (x - prev[0]), prev[1] + f * (y - prev[1]), prev[2] + f * dtheta))
        pose = Pose(float(x), float(y), float(theta))
        if use[i]:
            mapper.integrate(pose, log.ranges_m[i])
        mapper.mark_body(pose)
        prev = log.poses[i]
    mapper.finalize()
    return ReplayResult(
        log=log.directory,
        kind="udacity",
        frame=frame,
        mapper=mapper,
        slam=slam,
        sweep_poses=np.column_stack([log.t_s, log.poses])[use],
        steps=len(log.t_s),
        log_duration_s=float(log.t_s[-1] - log.t_s[0]),
        wall_time_s=time.perf_counter() - wall0,
    )


# -- the command -------------------------------------------------------------------------------------
def replay_path(log: Path | str, config: Path | str | None = None, resolution: float | None = None) -> ReplayResult:
    """Replay whatever ``log`` is: a Udacity directory, a sensors.log, or a directory holding one."""
    p = Path(log)
    if p.name in UDACITY_FILES and p.is_file():
        p = p.parent
    if p.is_dir():
        if any((p / name).exists() for name in UDACITY_FILES):
            cfg = load_run_config(config if config is not None else UDACITY_CONFIG, {"resolution": resolution})
            return replay_udacity(read_udacity_log(p), cfg.robot, cfg.slam)
        if (p / SENSOR_LOG_NAME).is_file():
            return replay_sensor_log(p / SENSOR_LOG_NAME, config, resolution)
        raise LogFormatError(f"{p}: no measurement.txt + poses.txt and no {SENSOR_LOG_NAME} in this directory")
    if not p.exists():
        raise LogFormatError(f"{p}: no such file or directory")
    return replay_sensor_log(p, config, resolution)


def replay_summary(result: ReplayResult, states: NDArray[np.int8], grid: GridSpec) -> dict[str, Any]:
    final_pose = None
    if result.sweeps:
        _, x, y, theta = (float(v) for v in result.sweep_poses[-1])
        final_pose = [round(x, 4), round(y, 4), round(math.remainder(theta, 2 * math.pi), 4)]
    return {
        "log": str(result.log),
        "format": result.kind,
        "mapper": result.slam.mapper,
        "resolution": grid.resolution,
        "steps": result.steps,
        "sweeps": result.sweeps,
        "grid": {
            "origin": [round(grid.origin_x, 6), round(grid.origin_y, 6)],
            "resolution": grid.resolution,
            "rows": grid.rows,
            "cols": grid.cols,
        },
        "cells": {
            "free": int(np.count_nonzero(states == FREE)),
            "occupied": int(np.count_nonzero(states == OCCUPIED)),
            "unknown": int(np.count_nonzero(states == UNKNOWN)),
        },
        "final_pose": final_pose,
        "log_duration_s": round(result.log_duration_s, 3),
        "wall_time_s": round(result.wall_time_s, 3),
        # A log from another version: its map can differ from the one the run exported.
        **({"ignored_settings": result.ignored_settings} if result.ignored_settings else {}),
    }


def run_replay(args: argparse.Namespace) -> int:
    """``sonarslam replay``: map a log; write the map files with --out; summary or JSON on stdout."""
    result = replay_path(args.log, args.config, args.resolution)
    states, grid = result.exported()
    summary = replay_summary(result, states, grid)
    if args.out:
        out = Path(args.out)
        paths = write_map_files(out, states, grid)
        atomic_write_bytes(out / "replay.json", (json.dumps(summary, indent=2) + "\n").encode())
        summary["files"] = {k: str(v) for k, v in paths.items()}
    if args.json:
        print(json.dumps(summary, separators=(",", ":")))
        return 0
    cells = summary["cells"]
    print(
        f"{result.log} ({result.kind} log): {result.sweeps} sweeps over {result.log_duration_s:.1f} s, "
        f"mapped with {result.slam.mapper} in {result.wall_time_s:.2f} s"
    )
    print(
        f"map {grid.cols} x {grid.rows} cells of {grid.resolution} m "
        f"from ({grid.origin_x:.2f}, {grid.origin_y:.2f}) m: "
        f"{cells['free']} free, {cells['occupied']} occupied, {cells['unknown']} unknown"
    )
    if result.ignored_settings:
        print(f"note: the log's settings {', '.join(result.ignored_settings)} are unknown to this version")
    if args.out:
        print(f"wrote {args.out}/map.csv, map.png, map.pgm, map.yaml, replay.json")
    return 0
