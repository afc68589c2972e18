"""Mappers that turn sonar sweeps at estimated poses into an occupancy grid."""

from __future__ import annotations

from typing import TYPE_CHECKING

from robot.config import RobotConfig
from robot.errors import ConfigError
from robot.mapping.base import MapFrame, Mapper

if TYPE_CHECKING:
    from robot.slam_config import SlamConfig


def make_mapper(name: str, frame: MapFrame, robot: RobotConfig, config: SlamConfig) -> Mapper:
    """Build the mapper called ``name`` (``logodds`` or ``paper``)."""
    if name == "logodds":
        from robot.mapping.logodds import LogOddsMapper

        return LogOddsMapper(frame, robot, config.logodds)
    if name == "paper":
        from robot.mapping.paper import PaperMapper

        return PaperMapper(frame, robot)
    raise ConfigError(f"unknown mapper {name!r} (expected logodds or paper)")


__all__ = ["MapFrame", "Mapper", "make_mapper"]
