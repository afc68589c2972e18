"""Turning run options into a validated, ready-to-run plan: world, robot, noise, SLAM settings, grid, truth."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from pydantic import ValidationError

from robot.config import RobotConfig, SimNoise, error_message
from robot.errors import ConfigError, WorldError
from robot.grid import GridSpec
from robot.mapping.base import MapFrame
from robot.runner import frame_for_unknown_room, frame_for_world
from robot.settings import load_run_config
from robot.sim.simulator import check_start
from robot.slam_config import SlamConfig
from robot.truth import truth_grid
from robot.world import World
from server.errors import field_error
from server.models import RunDefaults, RunOptions
from server.worlds import WorldCatalog

SLAM_OPTIONS = ("resolution", "mapper", "time_limit_s", "max_steps", "end_when_mapped")
MAX_NOISE_VALUE = 1e3  # no noise setting is sensible beyond this, whatever its unit


@dataclass(frozen=True)
class RunPlan:
    """Everything a run needs, checked before it is accepted."""

    options: dict[str, Any]  # the merged RunDefaults fields
    hardware: str
    world: World | None
    world_text: str | None
    robot: RobotConfig
    noise: SimNoise
    slam: SlamConfig
    frame: MapFrame
    truth: NDArray[np.int8] | None

    @property
    def grid(self) -> GridSpec:
        return self.frame.grid

    @property
    def speed(self) -> float | None:
        """The simulator's real-time factor, None for as fast as possible."""
        speed = self.options["speed"]
        return None if speed == "max" else float(speed)


def merge_options(defaults: RunDefaults, given: RunOptions) -> dict[str, Any]:
    """The defaults with every field the client gave replaced."""
    merged = defaults.model_dump()
    merged.update(given.model_dump(exclude_none=True))
    return merged


def _slam_field(message: str) -> str:
    for name in SLAM_OPTIONS:
        if name in message:
            return name
    return "resolution"  # the remaining checks (navigation cell, evidence grid) all hinge on it


def check_noise(base: SimNoise, noise: dict[str, float] | str, loc: list[str | int]) -> SimNoise:
    if noise == "off":
        return SimNoise.off()
    assert isinstance(noise, dict)
    for key, value in noise.items():
        if not math.isfinite(value) or abs(value) > MAX_NOISE_VALUE:
            raise field_error([*loc, key], f"must be a finite number within +-{MAX_NOISE_VALUE:g}")
    try:
        return SimNoise.model_validate(base.model_dump() | noise)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = [*loc, *(str(p) for p in err["loc"])]
        raise field_error(where, error_message(err)) from None


def robot_for(hardware: str, pi_config_file: Path | None) -> RobotConfig | None:
    """The Pi's robot description comes with its wiring file; the simulator uses the run configuration's."""
    if hardware != "pi":
        return None
    from robot.pi.config import load_pi_setup  # no hardware library is imported by this module

    return load_pi_setup(pi_config_file).robot


def validate_options(
    options: dict[str, Any],
    catalog: WorldCatalog,
    hardware: str,
    run_config_file: Path | None,
    max_grid_cells: int,
    pi_config_file: Path | None = None,
    loc: tuple[str, ...] = ("body",),
    with_truth: bool = False,
) -> RunPlan:
    """Check every option against the SLAM core's own validation; raise a 422 naming the field at fault."""
    try:
        cfg = load_run_config(
            run_config_file,
            {k: options[k] for k in SLAM_OPTIONS},
        )
    except ConfigError as exc:
        raise field_error([*loc, _slam_field(str(exc))], str(exc)) from None
    robot = robot_for(hardware, pi_config_file) or cfg.robot
    try:
        cfg.slam.check_robot(robot)
    except ConfigError as exc:
        raise field_error([*loc, "resolution"], str(exc)) from None
    noise = check_noise(cfg.noise, options["noise"], [*loc, "noise"])
    world: World | None = None
    world_text: str | None = None
    if hardware == "sim":
        world = catalog.load(options["world"])
        try:
            check_start(world, robot)
        except WorldError as exc:
            raise field_error([*loc, "world"], str(exc)) from None
        world_text = catalog.text(options["world"])
        frame = frame_for_world(world, cfg.slam.resolution)
    else:
        frame = frame_for_unknown_room(cfg.slam.resolution, cfg.slam.unknown_room_size_m)
    cells = frame.grid.rows * frame.grid.cols
    if cells > max_grid_cells:
        raise field_error(
            [*loc, "resolution"],
            f"resolution {cfg.slam.resolution} m gives a {frame.grid.rows} x {frame.grid.cols} grid "
            f"({cells} cells, more than the limit of {max_grid_cells}); use a coarser map",
        )
    truth = None
    if with_truth and world is not None:
        _grid, truth = truth_grid(world, cfg.slam.resolution)
    return RunPlan(
        options=dict(options),
        hardware=hardware,
        world=world,
        world_text=world_text,
        robot=robot,
        noise=noise,
        slam=cfg.slam,
        frame=frame,
        truth=truth,
    )
