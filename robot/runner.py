"""Simulated runs end to end: build the simulator and the engine, explore, score, write the outputs.

This is harness code: it holds both the simulator (which knows the world) and the engine (which
does not), and only compares them after the fact for scoring and the trajectory file.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robot.config import RobotConfig, SimNoise
from robot.engine import SlamEngine, StepResult
from robot.grid import GridSpec
from robot.mapio import atomic_write_bytes, write_csv, write_map_files, write_png
from robot.mapping.base import MapFrame
from robot.metrics import MapMetrics, score
from robot.sensorlog import SensorLogWriter
from robot.sim import SimRobot
from robot.slam_config import SlamConfig
from robot.truth import truth_grid
from robot.world import Pose, World


def frame_for_world(world: World, resolution: float) -> MapFrame:
    """What the SLAM side is told, as in the paper: the map size (the room's surveyed bounding box),
    the resolution and the start pose. Nothing about obstacles."""
    return MapFrame(grid=world.grid(resolution), start=world.start, extent=world.bounds)


def frame_for_unknown_room(resolution: float, size_m: float) -> MapFrame:
    """An unknown room (real hardware): a square grid of about ``size_m`` centred on the start,
    which is the origin of the odometry frame."""
    n = max(1, math.ceil(size_m / resolution))
    half = n * resolution / 2.0
    grid = GridSpec(origin_x=-half, origin_y=-half, resolution=resolution, rows=n, cols=n)
    return MapFrame(grid=grid, start=Pose(0.0, 0.0, 0.0), extent=None)


def log_metadata(robot: RobotConfig, frame: MapFrame, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Header for a sensor log: the sonar layout and the map frame, enough to replay it."""
    g = frame.grid
    return {
        "sonars": [m.model_dump() for m in robot.sonars],
        "sonar": robot.sonar.model_dump(),
        "robot": {k: v for k, v in robot.model_dump().items() if k not in ("sonars", "sonar")},
        "frame": {
            "origin": [g.origin_x, g.origin_y],
            "resolution": g.resolution,
            "rows": g.rows,
            "cols": g.cols,
            "start": [frame.start.x, frame.start.y, frame.start.theta],
            "extent": list(frame.extent) if frame.extent is not None else None,
        },
        **(extra or {}),
    }


@dataclass
class RunResult:
    world: str
    grid: GridSpec
    states: NDArray[np.int8]
    truth: NDArray[np.int8]
    metrics: MapMetrics
    steps: int
    sim_time_s: float
    wall_time_s: float
    terminated_by: str
    final_xy_error_m: float
    final_theta_error_deg: float
    trajectory: list[tuple[float, float, float, float, float, float, float]] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    def summary(self, resolution: float, seed: int, mapper: str) -> dict[str, Any]:
        return {
            "world": self.world,
            "resolution": resolution,
            "mapper": mapper,
            "seed": seed,
            "rows": self.grid.rows,
            "cols": self.grid.cols,
            "steps": self.steps,
            "sim_time_s": round(self.sim_time_s, 3),
            "wall_time_s": round(self.wall_time_s, 3),
            "terminated_by": self.terminated_by,
            "metrics": {k: (round(v, 6) if isinstance(v, float) else v) for k, v in self.metrics.as_dict().items()},
            "pose_error": {
                "final_xy_m": round(self.final_xy_error_m, 4),
                "final_theta_deg": round(self.final_theta_error_deg, 3),
            },
            **self.extra,
        }


def pose_errors(engine: SlamEngine, sim: SimRobot) -> tuple[float, float]:
    est = engine.pose
    true = sim.true_pose
    dtheta = math.degrees(math.atan2(math.sin(est.theta - true.theta), math.cos(est.theta - true.theta)))
    return math.hypot(est.x - true.x, est.y - true.y), abs(dtheta)


def simulate(
    world: World,
    robot: RobotConfig,
    noise: SimNoise,
    slam: SlamConfig,
    seed: int = 0,
    on_step: Callable[[StepResult], None] | None = None,
    log_path: Path | None = None,
) -> RunResult:
    """Explore ``world`` in the simulator until the engine terminates, then score the map.

    With ``log_path`` every sensor reading the SLAM side used is written there for ``replay``.
    """
    wall0 = time.perf_counter()
    grid, truth = truth_grid(world, slam.resolution)
    sim = SimRobot(world, robot, noise, seed=seed)
    frame = frame_for_world(world, slam.resolution)
    recorder = None
    if log_path is not None:
        meta = log_metadata(robot, frame, {"world": world.name, "seed": seed, "slam": slam.model_dump()})
        recorder = SensorLogWriter(log_path, meta)
    engine = SlamEngine(sim, robot, slam, frame, recorder=recorder)
    trajectory: list[tuple[float, float, float, float, float, float, float]] = []

    def record() -> None:
        est, true = engine.pose, sim.true_pose
        trajectory.append((sim.now(), est.x, est.y, est.theta, true.x, true.y, true.theta))

    record()
    try:
        while not engine.done:
            result = engine.step()
            record()
            if on_step is not None:
                on_step(result)
    finally:
        if recorder is not None:
            recorder.close()
    states = engine.map_states()
    xy_err, th_err = pose_errors(engine, sim)
    return RunResult(
        world=world.name,
        grid=grid,
        states=states,
        truth=truth,
        metrics=score(states, truth),
        steps=engine.stats.steps,
        sim_time_s=sim.now(),
        wall_time_s=time.perf_counter() - wall0,
        terminated_by=engine.stats.terminated_by or "unknown",
        final_xy_error_m=xy_err,
        final_theta_error_deg=th_err,
        trajectory=trajectory,
        extra={
            "collisions": sim.collisions,
            "failed_moves": engine.stats.failed_moves,
            "heading_fixes": len(engine.fixes.heading_fixes),
            "line_fixes": 0 if engine.fixes.lines is None else engine.fixes.lines.fixes,
            "bump_fixes": engine.fixes.contact_fixes,
            "map_repairs": engine.mapper.repairs,
            "sweeps": engine.stats.sweeps,
            "distance_m": round(sim.odometer_m, 3),
        },
    )


def trajectory_csv(rows: Sequence[tuple[float, ...]]) -> str:
    lines = ["t_s,est_x_m,est_y_m,est_theta_rad,true_x_m,true_y_m,true_theta_rad"]
    lines += [",".join(f"{v:.4f}" for v in row) for row in rows]
    return "\n".join(lines) + "\n"


def write_run_outputs(out_dir: Path, result: RunResult, summary: dict[str, Any]) -> None:
    """map.csv/png/pgm/yaml, truth.csv/png, trajectory.csv and run.json, each written atomically."""
    out_dir.mkdir(parents=True, exist_ok=True)
    write_map_files(out_dir, result.states, result.grid)
    write_csv(out_dir / "truth.csv", result.truth)
    write_png(out_dir / "truth.png", result.truth)
    atomic_write_bytes(out_dir / "trajectory.csv", trajectory_csv(result.trajectory).encode())
    atomic_write_bytes(out_dir / "run.json", (json.dumps(summary, indent=2) + "\n").encode())
