"""Run configuration for the SLAM loop: map, mapper, exploration, motion and localisation settings."""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from robot.boxfix import BoxFixConfig
from robot.config import CONFIG_DIR, RobotConfig, error_message, format_validation_error
from robot.errors import ConfigError
from robot.headingfix import HeadingFixConfig
from robot.linefix import LineFixConfig
from robot.localization import LocalizationConfig
from robot.mapping.logodds import LogOddsParams
from robot.motion import MotionConfig

DEFAULT_SLAM_FILE = CONFIG_DIR / "slam.toml"
MAPPERS = ("logodds", "paper")


class SlamConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    resolution: float = Field(default=0.2, ge=0.02, le=1.0)  # map cell side [m]
    mapper: Literal["logodds", "paper"] = "logodds"
    nav_cell_min_m: float | None = Field(default=None, gt=0.0, le=2.0)  # None: body + turning radius
    time_limit_s: float = Field(default=1200.0, gt=0.0)  # stop when the map has not changed this long
    max_sim_time_s: float = Field(default=6 * 3600.0, gt=0.0)  # safety cap on clock time
    max_steps: int = Field(default=20000, ge=1)  # safety cap on steps
    max_inspections: int = Field(default=2, ge=1, le=10)
    # Also inspect occupied cells between the explored area and unknown space (a false echo may close
    # off a passage). Off by default: over 6 seeds of 8 worlds it moved F1 by +0.001 (noise) and took
    # 30-40 % more steps.
    inspect_walls: bool = False
    # End once no unresolved cell touches the reachable area, the map (the mapper's belief) has not
    # changed for settle_steps steps and no occupied cell stands alone in free floor. An open room is
    # mapped long before it is walked: room1 is done after 118-161 of its 736 steps. False walks
    # the depth-first visit of every navigation cell to its end first, as the paper's robot does.
    end_when_mapped: bool = True
    settle_steps: int = Field(default=40, ge=0)
    # With end_when_mapped: once the map has not changed for this many steps while unresolved cells
    # remain, head for them instead of walking on depth-first through explored floor.
    seek_frontier_steps: int = Field(default=80, ge=1)
    # ... and once it has not changed for this many, give up the unresolved cells that no cell beside
    # them can be reached from, and take a black cell alone in free floor that the sweeps have not
    # cleared for a chair leg, rather than walk on through the rest of the room to the time limit.
    give_up_steps: int = Field(default=300, ge=1)
    # When nothing else is left, drive into a cell that only echoes hold occupied where the floor
    # straight beyond it has been seen free but cannot be reached: sonar arcs close a gap a little
    # wider than the robot (furniture beside a doorway). It arrives, or stalls and marks the cell
    # bumped. At most this many a run (0: never).
    max_probes: int = Field(default=8, ge=0)
    # A robot about to end its run boxed in (every way out stalled, its escapes spent) may first be
    # pinned against what it grazes: a centimetre of position error in a slot barely wider than the
    # body turns each move a fraction of a degree into the furniture. As a last resort it backs off
    # sideways, off the line of the move that failed, by ``unpin_m`` (one side, else the other), and
    # tries its moves again. At most this many times a run (0: never); no other run changes.
    max_unpins: int = Field(default=2, ge=0, le=20)
    unpin_m: float = Field(default=0.03, gt=0.0, le=0.2)
    unknown_room_size_m: float = Field(default=12.0, gt=0.5, le=100.0)  # grid side when the room size is unknown
    logodds: LogOddsParams = LogOddsParams()
    motion: MotionConfig = MotionConfig()
    localization: LocalizationConfig = LocalizationConfig()
    box_fix: BoxFixConfig = BoxFixConfig()
    heading_fix: HeadingFixConfig = HeadingFixConfig()
    line_fix: LineFixConfig = LineFixConfig()

    def nav_block(self, robot: RobotConfig) -> int:
        """Map cells per navigation-cell side: enough to hold the body and its turning circle."""
        need = self.nav_cell_min_m if self.nav_cell_min_m is not None else robot.diameter_m + robot.turning_radius_m
        return max(1, math.ceil(need / self.resolution - 1e-9))

    @model_validator(mode="after")
    def _sane(self) -> SlamConfig:
        if self.resolution < self.logodds.fine_cell_m * 0.999 and self.mapper == "logodds":
            raise ValueError(
                f"resolution {self.resolution} m is finer than the evidence grid ({self.logodds.fine_cell_m} m); "
                "lower fine_cell_m under [slam.logodds] too"
            )
        return self

    def check_robot(self, robot: RobotConfig) -> None:
        """Refuse settings that cannot work with this robot."""
        cell = self.nav_block(robot) * self.resolution
        if cell < robot.diameter_m:
            raise ConfigError(
                f"navigation cell {cell:.3f} m is smaller than the robot ({robot.diameter_m} m): raise nav_cell_min_m"
            )
        if self.nav_block(robot) > 40:
            raise ConfigError(
                f"resolution {self.resolution} m needs {self.nav_block(robot)} map cells per navigation cell; "
                "use a coarser map"
            )


def slam_config_from_dict(
    data: dict[str, Any], source: str = "slam config", given: dict[str, Any] | None = None
) -> SlamConfig:
    """Validate ``data`` (read from ``source``, with the ``given`` settings on top). A bad value that
    was given (on the command line, in a request) is named as such, not blamed on ``source``."""
    try:
        return SlamConfig.model_validate(data)
    except ValidationError as exc:
        for err in exc.errors():
            msg = error_message(err)
            # A check across settings has no field; its message starts with the setting it refuses.
            key = str(err["loc"][0]) if err["loc"] else next((k for k in given or {} if msg.startswith(f"{k} ")), "")
            if given and key in given:
                raise ConfigError(f"{key} = {given[key]!r}: {msg}") from None
        raise ConfigError(format_validation_error(source, exc)) from None
