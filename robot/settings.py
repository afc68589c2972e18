"""Loading a run's full configuration: the robot, the simulator's noise and the SLAM settings."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from robot.config import DEFAULT_ROBOT_FILE, RobotConfig, SimNoise, read_toml, robot_from_dict
from robot.errors import ConfigError
from robot.slam_config import DEFAULT_SLAM_FILE, SlamConfig, slam_config_from_dict

ROBOT_TABLES = ("robot", "sonar", "sonars", "imu", "sim_noise")


@dataclass(frozen=True)
class RunConfig:
    robot: RobotConfig
    noise: SimNoise
    slam: SlamConfig


def _merge(base: dict[str, Any], top: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in top.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def load_run_config(path: Path | str | None = None, slam_overrides: dict[str, Any] | None = None) -> RunConfig:
    """Defaults from ``config/robot.toml`` and ``config/slam.toml``; a user file may override any table.

    A user file holds ``[slam]`` (with ``[slam.logodds]``, ``[slam.motion]``, ...), ``[sim_noise]``
    and the robot tables (``[robot]``, ``[sonar]``, ``[[sonars]]``, ``[imu]``). Unknown tables are errors.
    """
    robot_data = read_toml(DEFAULT_ROBOT_FILE)
    slam_data = read_toml(DEFAULT_SLAM_FILE).get("slam", {}) if DEFAULT_SLAM_FILE.exists() else {}
    source = str(path) if path is not None else str(DEFAULT_SLAM_FILE)
    if path is not None:
        user = read_toml(Path(path))
        unknown = sorted(set(user) - {"slam", *ROBOT_TABLES})
        if unknown:
            raise ConfigError(f"{path}: unknown table [{unknown[0]}] (expected slam, {', '.join(ROBOT_TABLES)})")
        robot_data = _merge(robot_data, {k: v for k, v in user.items() if k in ROBOT_TABLES})
        slam_data = _merge(slam_data, user.get("slam", {}))
    given = {key: value for key, value in (slam_overrides or {}).items() if value is not None}
    slam_data.update(given)
    robot, noise = robot_from_dict(robot_data, source)
    slam = slam_config_from_dict(slam_data, source, given)
    slam.check_robot(robot)
    return RunConfig(robot, noise, slam)
