"""Robot description and simulator noise settings, validated and loaded from TOML in ``config/``."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import ErrorDetails

from robot.errors import ConfigError

CONFIG_DIR = Path(__file__).resolve().parent.parent / "config"
DEFAULT_ROBOT_FILE = CONFIG_DIR / "robot.toml"


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class SonarMount(_Frozen):
    """One sonar on the robot body, in the robot frame (x forward, y left)."""

    bearing_deg: float = Field(ge=-360.0, le=360.0)  # beam axis, counter-clockwise from forward
    offset_x_m: float = Field(default=0.0, ge=-1.0, le=1.0)
    offset_y_m: float = Field(default=0.0, ge=-1.0, le=1.0)


class SonarModel(_Frozen):
    """What every sonar of the ring shares (HC-SR04 defaults)."""

    beam_width_deg: float = Field(default=30.0, gt=0.0, lt=170.0)  # full cone angle
    min_range_m: float = Field(default=0.02, ge=0.0)
    max_range_m: float = Field(default=4.0, gt=0.0, le=20.0)  # a reading at or above this means "no echo"
    ping_interval_s: float = Field(default=0.06, ge=0.0)  # gap between consecutive pings
    firing_order: tuple[int, ...] = (0, 3, 6, 1, 4, 7, 2, 5)  # neither neighbours nor opposites back to back

    @model_validator(mode="after")
    def _ranges(self) -> SonarModel:
        if self.min_range_m >= self.max_range_m:
            raise ValueError("min_range_m must be below max_range_m")
        return self


class ImuModel(_Frozen):
    rate_hz: float = Field(default=100.0, gt=0.0, le=2000.0)


class RobotConfig(_Frozen):
    """The physical robot: body, wheels, encoders, sonar ring and IMU."""

    name: str = "sonarslam-bot"
    diameter_m: float = Field(default=0.1275, gt=0.0, le=2.0)
    wheel_radius_m: float = Field(default=0.032, gt=0.0, le=0.5)
    wheel_base_m: float = Field(default=0.105, gt=0.0, le=2.0)  # distance between wheel contact points
    encoder_counts_per_rev: int = Field(default=48, ge=1)
    max_wheel_speed_m_s: float = Field(default=0.25, gt=0.0, le=5.0)
    turning_radius_m: float = Field(default=0.07, ge=0.0)  # extra clearance needed while turning [m]
    sonar: SonarModel = SonarModel()
    sonars: tuple[SonarMount, ...] = ()
    imu: ImuModel = ImuModel()

    @model_validator(mode="after")
    def _layout(self) -> RobotConfig:
        if not self.sonars:
            radius = self.diameter_m / 2.0
            mounts = tuple(
                SonarMount(
                    bearing_deg=45.0 * i,
                    offset_x_m=round(radius * math.cos(math.radians(45.0 * i)), 6),
                    offset_y_m=round(radius * math.sin(math.radians(45.0 * i)), 6),
                )
                for i in range(8)
            )
            object.__setattr__(self, "sonars", mounts)
        order = self.sonar.firing_order
        if sorted(order) != list(range(len(self.sonars))):
            raise ValueError(f"sonar.firing_order {list(order)} must list each of the {len(self.sonars)} sonars once")
        if self.wheel_base_m < self.diameter_m / 4:
            raise ValueError("wheel_base_m is implausibly small for the body diameter")
        return self

    @property
    def radius_m(self) -> float:
        return self.diameter_m / 2.0

    @property
    def metres_per_count(self) -> float:
        return 2.0 * math.pi * self.wheel_radius_m / self.encoder_counts_per_rev

    @property
    def sonar_bearings_rad(self) -> list[float]:
        return [math.radians(m.bearing_deg) for m in self.sonars]


class SimNoise(_Frozen):
    """Every error the simulator can inject; ``SimNoise.off()`` makes the simulator exact."""

    range_noise_m: float = Field(default=0.01, ge=0.0)  # constant part of the range std-dev
    range_noise_frac: float = Field(default=0.01, ge=0.0)  # part proportional to range
    range_quantum_m: float = Field(default=0.01, ge=0.0)  # reading resolution, 0 = continuous
    specular_onset_deg: float = Field(default=20.0, ge=0.0, le=90.0)  # incidence where misses begin
    specular_full_deg: float = Field(default=45.0, ge=0.0, le=90.0)  # incidence where misses reach the max
    specular_miss_prob: float = Field(default=0.85, ge=0.0, le=1.0)  # miss probability at and past full
    false_echo_prob: float = Field(default=0.01, ge=0.0, le=1.0)  # short spurious echo
    dropout_prob: float = Field(default=0.01, ge=0.0, le=1.0)  # reading lost: reports max range
    wheel_slip_std: float = Field(default=0.02, ge=0.0, le=0.5)  # per-tick relative ground-speed error
    wheel_radius_error_left: float = Field(default=0.004, ge=-0.2, le=0.2)  # true/nominal - 1
    wheel_radius_error_right: float = Field(default=-0.004, ge=-0.2, le=0.2)
    gyro_noise_std_rad_s: float = Field(default=0.0015, ge=0.0)  # white noise per sample
    gyro_bias_rad_s: float = Field(default=0.015, ge=-1.0, le=1.0)  # constant bias at start
    gyro_bias_walk_rad_s2: float = Field(default=0.0003, ge=0.0)  # bias random walk [rad/s/sqrt(s)]

    @model_validator(mode="after")
    def _specular(self) -> SimNoise:
        if self.specular_full_deg < self.specular_onset_deg:
            raise ValueError("specular_full_deg must not be below specular_onset_deg")
        return self

    @classmethod
    def off(cls) -> SimNoise:
        return cls(
            range_noise_m=0.0,
            range_noise_frac=0.0,
            range_quantum_m=0.0,
            specular_miss_prob=0.0,
            false_echo_prob=0.0,
            dropout_prob=0.0,
            wheel_slip_std=0.0,
            wheel_radius_error_left=0.0,
            wheel_radius_error_right=0.0,
            gyro_noise_std_rad_s=0.0,
            gyro_bias_rad_s=0.0,
            gyro_bias_walk_rad_s2=0.0,
        )


def error_message(err: ErrorDetails) -> str:
    """A validation error's message without pydantic's "Value error, " prefix."""
    return str(err["msg"]).removeprefix("Value error, ")


def error_line(err: ErrorDetails) -> str:
    """``field.path: message``, or the message alone for a check across fields (it names them itself)."""
    where = ".".join(str(p) for p in err["loc"])
    return f"{where}: {error_message(err)}" if where else error_message(err)


def format_validation_error(source: str, exc: ValidationError) -> str:
    """One line naming the source and every offending field, so that a file with several mistakes
    is fixed in one go."""
    return f"{source}: {'; '.join(error_line(err) for err in exc.errors())}"


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file, turning every failure into a ConfigError naming the file."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a directory, expected a TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None


def robot_from_dict(data: dict[str, Any], source: str = "robot config") -> tuple[RobotConfig, SimNoise]:
    """Build the robot description and simulator noise from a parsed ``robot.toml``."""
    data = dict(data)
    noise_data = data.pop("sim_noise", {})
    try:
        robot = RobotConfig.model_validate(data.get("robot", {}) | {k: v for k, v in data.items() if k != "robot"})
        noise = SimNoise.model_validate(noise_data)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(source, exc)) from None
    return robot, noise


def load_robot_config(path: Path | str | None = None) -> tuple[RobotConfig, SimNoise]:
    """Load ``config/robot.toml`` (or another file) into a RobotConfig and the default SimNoise."""
    p = Path(path) if path is not None else DEFAULT_ROBOT_FILE
    return robot_from_dict(read_toml(p), str(p))
