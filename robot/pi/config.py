"""Raspberry Pi wiring (GPIO pins, I2C buses and addresses) validated and loaded from ``config/robot-pi.toml``."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from robot.config import CONFIG_DIR, RobotConfig, error_line, load_robot_config, read_toml
from robot.errors import ConfigError

DEFAULT_PI_FILE = CONFIG_DIR / "robot-pi.toml"

# BCM GPIO number on the 40-pin header (GPIO0/1 are the HAT EEPROM pins but still usable).
PinNumber = Annotated[int, Field(ge=0, le=27)]
I2cBusNumber = Annotated[int, Field(ge=0, le=31)]
Axis = Literal["+x", "-x", "+y", "-y", "+z", "-z"]
Decoding = Literal["x1", "x2", "x4"]

EDGES_PER_PULSE: dict[str, int] = {"x1": 1, "x2": 2, "x4": 4}
# I2C bus 1 is wired to fixed header pins; bus 0 (GPIO0/1) is the HAT EEPROM bus.
I2C_BUS_PINS: dict[int, tuple[tuple[int, str], ...]] = {1: ((2, "SDA"), (3, "SCL")), 0: ((0, "SDA"), (1, "SCL"))}


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


def axis_vector(axis: str) -> tuple[int, int, int]:
    """'+x' -> (1, 0, 0), '-z' -> (0, 0, -1)."""
    sign = -1 if axis[0] == "-" else 1
    index = "xyz".index(axis[1])
    return tuple(sign if i == index else 0 for i in range(3))  # type: ignore[return-value]


def _cross(a: tuple[int, int, int], b: tuple[int, int, int]) -> tuple[int, int, int]:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _check_address(address: int, low: int, high: int, device: str) -> int:
    """Accept a 7-bit I2C address in [low, high]; recognise the 8-bit form datasheets often print."""
    if low <= address <= high:
        return address
    if address % 2 == 0 and low <= address // 2 <= high:
        raise ValueError(f"{address:#04x} is the 8-bit form; use the 7-bit address {address // 2:#04x}")
    raise ValueError(f"{device} I2C address {address:#04x} is outside {low:#04x}-{high:#04x}")


class HcSr04Pins(_Frozen):
    """One HC-SR04: trigger output and echo input (through a 5 V -> 3.3 V divider)."""

    trigger_pin: PinNumber
    echo_pin: PinNumber | None = None  # None when the ring uses shared_echo_pin


class HcSr04RingConfig(_Frozen):
    """HC-SR04 sonars on GPIO, listed in mounting order (sensors[i] is ``RobotConfig.sonars[i]``)."""

    kind: Literal["hcsr04"]
    sensors: tuple[HcSr04Pins, ...] = Field(min_length=1)
    # Since the ring fires one sonar at a time, all echo lines may be diode-OR'ed onto one input.
    shared_echo_pin: PinNumber | None = None
    speed_of_sound_m_s: float = Field(default=343.0, gt=300.0, lt=400.0)  # 343 m/s at 20 degC

    @model_validator(mode="after")
    def _echo_pins(self) -> HcSr04RingConfig:
        with_echo = [i for i, s in enumerate(self.sensors) if s.echo_pin is not None]
        if self.shared_echo_pin is None and len(with_echo) != len(self.sensors):
            missing = next(i for i in range(len(self.sensors)) if i not in with_echo)
            raise ValueError(f"sensors[{missing}] has no echo_pin and there is no shared_echo_pin")
        if self.shared_echo_pin is not None and with_echo:
            raise ValueError(f"sensors[{with_echo[0]}].echo_pin is set although shared_echo_pin is used")
        return self


class Srf02Sensor(_Frozen):
    address: int  # 7-bit address, 0x70-0x7F

    @field_validator("address")
    @classmethod
    def _address(cls, value: int) -> int:
        return _check_address(value, 0x70, 0x7F, "SRF02/SRF08")


class Srf02RingConfig(_Frozen):
    """SRF02/SRF08 sonars on one I2C bus, listed in mounting order."""

    kind: Literal["srf02"]
    bus: I2cBusNumber = 1
    sensors: tuple[Srf02Sensor, ...] = Field(min_length=1)
    ranging_time_s: float = Field(default=0.07, ge=0.07, le=0.5)  # the datasheet's 65 ms plus margin
    retries: int = Field(default=10, ge=0, le=100)  # re-tries while the sonar ignores the bus (errno 121)

    @model_validator(mode="after")
    def _unique(self) -> Srf02RingConfig:
        seen: dict[int, int] = {}
        for i, sensor in enumerate(self.sensors):
            if sensor.address in seen:
                first = seen[sensor.address]
                raise ValueError(f"I2C address {sensor.address:#04x} is used by sensors[{first}] and sensors[{i}]")
            seen[sensor.address] = i
        return self


class MotorPins(_Frozen):
    """One H-bridge channel: swap forward_pin and backward_pin if the wheel turns the wrong way."""

    forward_pin: PinNumber
    backward_pin: PinNumber
    enable_pin: PinNumber | None = None  # only for drivers with a separate enable input


class MotorsConfig(_Frozen):
    """Both H-bridge channels. Open loop: a wheel speed becomes a duty through ``max_wheel_speed_m_s``."""

    left: MotorPins
    right: MotorPins
    pwm_frequency_hz: float = Field(default=1000.0, gt=0.0, le=20000.0)
    # Dead-band compensation: the duty a non-zero command starts from (0 keeps duty = speed / max speed).
    min_duty: float = Field(default=0.0, ge=0.0, lt=1.0, allow_inf_nan=False)


class EncoderPins(_Frozen):
    a_pin: PinNumber
    b_pin: PinNumber | None = None  # None: single-channel, direction from the commanded motor sign
    reversed: bool = False  # flip the sign so that driving forward counts up


class EncodersConfig(_Frozen):
    """Wheel encoders; ``pulses_per_rev`` x the decoding's edges per pulse must equal the robot's counts per rev."""

    left: EncoderPins
    right: EncoderPins
    pulses_per_rev: int = Field(ge=1)  # pulses on channel A per *wheel* revolution (after the gearbox)
    decoding: Decoding = "x4"  # x1: A rising edges, x2: both A edges, x4: every A and B edge
    pull_up: bool = True  # open-collector Hall/optical outputs need the internal pull-up

    @model_validator(mode="after")
    def _channels(self) -> EncodersConfig:
        for side, pins in (("left", self.left), ("right", self.right)):
            if self.decoding == "x4" and pins.b_pin is None:
                raise ValueError(f"{side}: x4 decoding needs b_pin; use x1 or x2 for a single-channel encoder")
        return self

    @property
    def counts_per_rev(self) -> int:
        return self.pulses_per_rev * EDGES_PER_PULSE[self.decoding]


class ImuConfig(_Frozen):
    """MPU-6050 on I2C. The axes say which chip axis points forward, left and up on the robot."""

    enabled: bool = True
    bus: I2cBusNumber = 1
    address: int = 0x68  # 0x69 when AD0 is tied high
    calibration_samples: int = Field(default=500, ge=10, le=20000)  # gyro bias average, robot still
    still_max_std_dps: float = Field(default=1.0, gt=0.0)  # calibration fails if the gyro is noisier
    dlpf: int = Field(default=3, ge=0, le=6)  # CONFIG.DLPF_CFG; 3 gives about 42 Hz bandwidth
    forward_axis: Axis = "+x"
    left_axis: Axis = "+y"
    up_axis: Axis = "+z"

    @field_validator("address")
    @classmethod
    def _address(cls, value: int) -> int:
        return _check_address(value, 0x68, 0x69, "MPU-6050")

    @model_validator(mode="after")
    def _right_handed(self) -> ImuConfig:
        forward, left, up = (axis_vector(a) for a in (self.forward_axis, self.left_axis, self.up_axis))
        expected = _cross(forward, left)
        if up != expected:
            names = {axis_vector(a): a for a in ("+x", "-x", "+y", "-y", "+z", "-z")}
            hint = ""
            if expected in names:
                hint = f"; with these forward and left axes up_axis must be {names[expected]!r}"
            raise ValueError(
                f"forward_axis={self.forward_axis!r}, left_axis={self.left_axis!r}, up_axis={self.up_axis!r} "
                f"is not a right-handed frame{hint}"
            )
        return self


class SafetyConfig(_Frozen):
    watchdog_timeout_s: float = Field(default=0.5, gt=0.05, le=10.0)  # motors stop if the loop stalls longer


class PiConfig(_Frozen):
    """Everything wired to the Pi. Geometry and the sonar model come from ``robot_file``."""

    robot_file: str = "robot.toml"  # relative to this file's directory
    sonar_ring: Annotated[HcSr04RingConfig | Srf02RingConfig, Field(discriminator="kind")]
    motors: MotorsConfig
    encoders: EncodersConfig
    imu: ImuConfig = ImuConfig()
    safety: SafetyConfig = SafetyConfig()

    def i2c_devices(self) -> list[tuple[int, int, str]]:
        """(bus, address, use) for every I2C device in use."""
        devices: list[tuple[int, int, str]] = []
        if self.imu.enabled:
            devices.append((self.imu.bus, self.imu.address, "imu"))
        ring = self.sonar_ring
        if isinstance(ring, Srf02RingConfig):
            devices += [(ring.bus, s.address, f"sonar_ring.sensors[{i}]") for i, s in enumerate(ring.sensors)]
        return devices

    def pin_uses(self) -> list[tuple[int, str]]:
        """(GPIO, use) for every pin in use, I2C bus pins included."""
        uses: list[tuple[int, str]] = []
        ring = self.sonar_ring
        if isinstance(ring, HcSr04RingConfig):
            for i, s in enumerate(ring.sensors):
                uses.append((s.trigger_pin, f"sonar_ring.sensors[{i}].trigger_pin"))
                if s.echo_pin is not None:
                    uses.append((s.echo_pin, f"sonar_ring.sensors[{i}].echo_pin"))
            if ring.shared_echo_pin is not None:
                uses.append((ring.shared_echo_pin, "sonar_ring.shared_echo_pin"))
        for side, motor in (("left", self.motors.left), ("right", self.motors.right)):
            uses.append((motor.forward_pin, f"motors.{side}.forward_pin"))
            uses.append((motor.backward_pin, f"motors.{side}.backward_pin"))
            if motor.enable_pin is not None:
                uses.append((motor.enable_pin, f"motors.{side}.enable_pin"))
        for side, enc in (("left", self.encoders.left), ("right", self.encoders.right)):
            uses.append((enc.a_pin, f"encoders.{side}.a_pin"))
            if enc.b_pin is not None:
                uses.append((enc.b_pin, f"encoders.{side}.b_pin"))
        for bus in sorted({bus for bus, _, _ in self.i2c_devices()}):
            uses += [(pin, f"I2C bus {bus} {line}") for pin, line in I2C_BUS_PINS.get(bus, ())]
        return uses

    @model_validator(mode="after")
    def _no_conflicts(self) -> PiConfig:
        first_use: dict[int, str] = {}
        for pin, use in self.pin_uses():
            if pin in first_use:
                raise ValueError(f"GPIO{pin} is used twice: {first_use[pin]} and {use}")
            first_use[pin] = use
        seen: dict[tuple[int, int], str] = {}
        for bus, address, use in self.i2c_devices():
            if (bus, address) in seen:
                raise ValueError(f"I2C bus {bus} address {address:#04x} is used twice: {seen[bus, address]} and {use}")
            seen[bus, address] = use
        return self


@dataclass(frozen=True)
class PiSetup:
    """A validated Pi wiring together with the robot description it drives."""

    pi: PiConfig
    robot: RobotConfig
    path: Path  # the robot-pi.toml it came from


def _format_error(source: str, exc: ValidationError) -> str:
    """One line: the file, the offending field (if any) and the message without pydantic's prefix."""
    return f"{source}: {error_line(exc.errors()[0])}"


def pi_config_from_dict(data: dict[str, Any], source: str = "pi config") -> PiConfig:
    try:
        return PiConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(_format_error(source, exc)) from None


def check_against_robot(pi: PiConfig, robot: RobotConfig, source: str = "pi config") -> None:
    """The wiring must match the robot description: one sonar per mount, same counts per revolution."""
    n_wired, n_mounted = len(pi.sonar_ring.sensors), len(robot.sonars)
    if n_wired != n_mounted:
        raise ConfigError(f"{source}: sonar_ring lists {n_wired} sensors but the robot has {n_mounted} sonars")
    enc = pi.encoders
    if enc.counts_per_rev != robot.encoder_counts_per_rev:
        raise ConfigError(
            f"{source}: encoders: {enc.pulses_per_rev} pulses/rev x {EDGES_PER_PULSE[enc.decoding]} ({enc.decoding}) = "
            f"{enc.counts_per_rev} counts/rev, but encoder_counts_per_rev is {robot.encoder_counts_per_rev}"
        )


def load_pi_setup(path: Path | str | None = None) -> PiSetup:
    """Load ``config/robot-pi.toml`` (or another file) and the robot file it names; ConfigError on any problem."""
    p = Path(path) if path is not None else DEFAULT_PI_FILE
    pi = pi_config_from_dict(read_toml(p), str(p))
    robot_path = Path(pi.robot_file)
    if not robot_path.is_absolute():
        robot_path = p.parent / robot_path
    robot, _noise = load_robot_config(robot_path)
    check_against_robot(pi, robot, str(p))
    return PiSetup(pi=pi, robot=robot, path=p)
