"""``PiHardware``: the Hardware seam on a Raspberry Pi, assembled from the wiring in ``robot-pi.toml``."""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from robot.config import RobotConfig
from robot.errors import HardwareError
from robot.hardware import EncoderCounts, ImuSample, SonarSweep
from robot.pi.config import HcSr04RingConfig, PiSetup, load_pi_setup
from robot.pi.encoders import WheelEncoder
from robot.pi.i2c import BusFactory, LockedBus, open_smbus
from robot.pi.motors import DriveMotors
from robot.pi.mpu6050 import GyroCalibration, ImuSampler, Mpu6050
from robot.pi.sonar import SonarBank, SonarRing

SLEEP_SLICE_S = 0.1  # long sleeps are cut into slices so the watchdog keeps being fed
MOCK_PINS = "GPIOZERO_PIN_FACTORY=mock GPIOZERO_MOCK_PIN_CLASS=mockpwmpin"  # the motors need PWM-capable pins


class PiHardware:
    """Sonars, encoders, IMU and motors of the real robot behind the ``robot.hardware.Hardware`` protocol.

    Build it with :meth:`from_config`; the constructor takes ready-made parts so tests can swap any.
    Every hardware call reports activity to listeners (the safety watchdog feeds on it); after
    :meth:`halt` every call except ``stop``/``close`` raises ``HardwareError``.
    """

    def __init__(
        self,
        robot: RobotConfig,
        *,
        sonars: SonarRing,
        encoders: tuple[WheelEncoder, WheelEncoder],
        motors: DriveMotors,
        imu: ImuSampler | None = None,
        gyro_calibration: GyroCalibration | None = None,
        resources: list[Callable[[], None]] | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.robot = robot
        self.sonars = sonars
        self.encoders = encoders
        self.motors = motors
        self.imu = imu
        self.gyro_calibration = gyro_calibration
        self._resources = list(resources or [])  # extra closers (I2C buses), run last
        self._on_close: list[Callable[[], None]] = []  # run right after the motors close (see add_closer)
        self._clock = clock
        self._sleep = sleep
        self._listeners: list[Callable[[], None]] = []
        self._halted: str | None = None
        self._closed = False
        self._close_lock = threading.Lock()
        self.sonars.on_ping = self._activity  # a sweep takes about 0.5 s: feed the watchdog per ping

    # -- construction ------------------------------------------------------------------------

    @classmethod
    def from_config(
        cls,
        setup: PiSetup,
        *,
        pin_factory: Any = None,
        bus_factory: BusFactory | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        start_imu: bool = True,
    ) -> PiHardware:
        """Open every device named in ``setup``, calibrate the gyro (robot still) and start IMU sampling.

        ``pin_factory`` defaults to gpiozero's (lgpio on a Pi, or ``GPIOZERO_PIN_FACTORY``);
        ``bus_factory(n)`` opens I2C bus n and defaults to smbus2. Any failure closes what was
        opened and raises ``HardwareError`` with a one-line reason.
        """
        from gpiozero.exc import BadPinFactory, GPIOZeroError, PinPWMUnsupported

        pi, robot = setup.pi, setup.robot
        open_bus = bus_factory or open_smbus
        buses: dict[int, LockedBus] = {}

        def bus(number: int) -> LockedBus:
            if number not in buses:
                buses[number] = LockedBus(open_bus(number), number)
                stack.callback(buses[number].close)
            return buses[number]

        part = "setup"
        with contextlib.ExitStack() as stack:
            try:
                part = "sonars"
                bank = _open_sonar_bank(setup, bus, pin_factory, sleep)
                stack.callback(bank.close)
                part = "motors"
                motors = DriveMotors(
                    pi.motors.left,
                    pi.motors.right,
                    max_wheel_speed_m_s=robot.max_wheel_speed_m_s,
                    pwm_frequency_hz=pi.motors.pwm_frequency_hz,
                    min_duty=pi.motors.min_duty,
                    pin_factory=pin_factory,
                )
                stack.callback(motors.close)
                part = "encoders"
                encoders = []
                for pins in (pi.encoders.left, pi.encoders.right):
                    encoder = WheelEncoder(
                        pins.a_pin,
                        pins.b_pin,
                        decoding=pi.encoders.decoding,
                        reversed=pins.reversed,
                        pull_up=pi.encoders.pull_up,
                        pin_factory=pin_factory,
                    )
                    stack.callback(encoder.close)
                    encoders.append(encoder)
                part = "IMU"
                sampler = calibration = None
                if pi.imu.enabled:
                    sampler, calibration = _open_imu(setup, bus(pi.imu.bus), clock, sleep)
                    stack.callback(sampler.close)
            except BadPinFactory as exc:
                raise HardwareError(
                    f"no GPIO pin factory ({exc}): on a Raspberry Pi install lgpio (pip install 'sonarslam[pi]'); "
                    f"elsewhere set {MOCK_PINS} for a dry run"
                ) from None
            except PinPWMUnsupported:
                raise HardwareError(
                    f"{setup.path}: {part}: the pin factory cannot drive PWM on these pins; "
                    f"gpiozero's mock pins need {MOCK_PINS}"
                ) from None
            except (GPIOZeroError, OSError) as exc:
                raise HardwareError(f"{setup.path}: {part}: {exc or type(exc).__name__}") from None
            sonar = robot.sonar
            hw = cls(
                robot,
                sonars=SonarRing(
                    bank, sonar.firing_order, sonar.ping_interval_s, sonar.max_range_m, clock=clock, sleep=sleep
                ),
                encoders=(encoders[0], encoders[1]),
                motors=motors,
                imu=sampler,
                gyro_calibration=calibration,
                resources=[b.close for b in buses.values()],
                clock=clock,
                sleep=sleep,
            )
            stack.pop_all()
        if sampler is not None and start_imu:
            sampler.start()
        return hw

    @classmethod
    def open(cls, config_path: Path | str | None = None, **kwargs: Any) -> PiHardware:
        """``from_config(load_pi_setup(config_path))``; the default path is ``config/robot-pi.toml``."""
        return cls.from_config(load_pi_setup(config_path), **kwargs)

    # -- the Hardware protocol ---------------------------------------------------------------

    def now(self) -> float:
        return self._clock()

    def sleep(self, duration_s: float) -> None:
        end_s = self._clock() + duration_s
        while True:
            self._activity()
            remaining_s = end_s - self._clock()
            if remaining_s <= 0.0:
                return
            self._sleep(min(remaining_s, SLEEP_SLICE_S))

    def read_sonar_sweep(self) -> SonarSweep:
        self._activity()
        ranges_m = self.sonars.sweep()
        return SonarSweep(t_s=self._clock(), ranges_m=np.asarray(ranges_m, dtype=np.float64))

    def read_encoders(self) -> EncoderCounts:
        self._activity()
        left, right = self.encoders
        return EncoderCounts(t_s=self._clock(), left=left.count, right=right.count)

    def read_imu(self) -> list[ImuSample]:
        self._activity()
        return [] if self.imu is None else self.imu.drain()

    def set_wheel_speeds(self, left_m_s: float, right_m_s: float) -> None:
        self._activity()
        self.motors.set_speeds(left_m_s, right_m_s)
        for encoder, speed in zip(self.encoders, (left_m_s, right_m_s), strict=True):
            encoder.set_direction(speed)
        if self._halted is not None:  # halted while commanding (a signal between check and write)
            self.motors.stop()
            raise HardwareError(self._halted)

    def stop(self) -> None:
        self.motors.stop()

    def close(self) -> None:
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        closers: list[Callable[[], None]] = [self.motors.close, *reversed(self._on_close)]
        if self.imu is not None:
            closers.append(self.imu.close)
        closers += [self.sonars.close, *(e.close for e in self.encoders), *self._resources]
        errors: list[BaseException] = []
        for close in closers:  # the motors first; every device gets closed even if one fails
            try:
                close()
            except Exception as exc:
                errors.append(exc)
        if errors:
            raise HardwareError(f"closing the hardware failed: {errors[0]}")

    def __enter__(self) -> PiHardware:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- safety hooks ------------------------------------------------------------------------

    def add_closer(self, closer: Callable[[], None]) -> None:
        """``closer()`` runs once when the hardware closes, after the motors have stopped and before the
        sensors are released (the last one added runs first). For what must live exactly as long as
        the hardware, such as a safety guard around a control loop on a worker thread."""
        with self._close_lock:
            if not self._closed:
                self._on_close.append(closer)
                return
        closer()  # already closed: release it now

    def add_activity_listener(self, listener: Callable[[], None]) -> None:
        """``listener()`` runs on every hardware call (and every ping, every sleep slice)."""
        self._listeners.append(listener)

    def remove_activity_listener(self, listener: Callable[[], None]) -> None:
        with contextlib.suppress(ValueError):
            self._listeners.remove(listener)

    def halt(self, reason: str) -> None:
        """Stop the motors and refuse further commands: the run is over."""
        self._halted = reason
        self.motors.stop()

    @property
    def halted(self) -> str | None:
        return self._halted

    def _activity(self) -> None:
        if self._closed:
            raise HardwareError("the hardware is closed")
        if self._halted is not None:
            raise HardwareError(self._halted)
        for listener in tuple(self._listeners):
            listener()


def _open_sonar_bank(
    setup: PiSetup, bus: Callable[[int], LockedBus], pin_factory: Any, sleep: Callable[[float], None]
) -> SonarBank:
    ring, robot = setup.pi.sonar_ring, setup.robot
    if isinstance(ring, HcSr04RingConfig):
        from robot.pi.hcsr04 import HcSr04Bank

        shared = ring.shared_echo_pin
        echo_pins = [s.echo_pin if s.echo_pin is not None else shared for s in ring.sensors]
        return HcSr04Bank(
            [s.trigger_pin for s in ring.sensors],
            [pin for pin in echo_pins if pin is not None],  # the config guarantees one per sensor
            max_range_m=robot.sonar.max_range_m,
            speed_of_sound_m_s=ring.speed_of_sound_m_s,
            pin_factory=pin_factory,
        )
    from robot.pi.srf02 import Srf02Bank

    return Srf02Bank(
        bus(ring.bus),
        [s.address for s in ring.sensors],
        bus_number=ring.bus,
        max_range_m=robot.sonar.max_range_m,
        ranging_time_s=ring.ranging_time_s,
        retries=ring.retries,
        sleep=sleep,
    )


def _open_imu(
    setup: PiSetup, bus: LockedBus, clock: Callable[[], float], sleep: Callable[[float], None]
) -> tuple[ImuSampler, GyroCalibration]:
    """Identify and configure the MPU-6050, then calibrate its gyro while the robot stands still."""
    cfg, rate_hz = setup.pi.imu, setup.robot.imu.rate_hz
    imu = Mpu6050(
        bus,
        bus_number=cfg.bus,
        address=cfg.address,
        forward_axis=cfg.forward_axis,
        left_axis=cfg.left_axis,
        up_axis=cfg.up_axis,
        dlpf=cfg.dlpf,
        sample_rate_hz=rate_hz,
        sleep=sleep,
    )
    calibration = imu.calibrate(
        cfg.calibration_samples, 1.0 / rate_hz, still_max_std_dps=cfg.still_max_std_dps, sleep=sleep
    )
    return ImuSampler(imu, rate_hz, clock=clock), calibration
