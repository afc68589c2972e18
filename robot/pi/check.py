"""``sonarslam check-hardware``: bring-up report of IMU, sonars and encoders on the real robot."""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from robot.errors import ConfigError, HardwareError
from robot.pi.config import HcSr04RingConfig, PiSetup, load_pi_setup

EXIT_OK = 0
EXIT_BAD_SETUP = 2  # bad config, or hardware missing or not answering


def check_hardware(
    config_path: Path | str | None,
    duration_s: float,
    out: Callable[[str], None] = print,
    *,
    pin_factory: Any = None,
    bus_factory: Any = None,
    sleep: Callable[[float], None] = time.sleep,
) -> int:
    """Open the robot, print the IMU identity and sample rate, then sonar ranges and encoder counts
    once per sweep for ``duration_s`` while someone turns the wheels by hand. The motors stay off.

    Returns 0, or 2 with a one-line ``error:`` message for bad config or missing hardware.
    """
    try:
        setup = load_pi_setup(config_path)
    except ConfigError as exc:
        out(f"error: {exc}")
        return EXIT_BAD_SETUP
    out(_describe(setup))
    if setup.pi.imu.enabled:
        seconds = setup.pi.imu.calibration_samples / setup.robot.imu.rate_hz
        out(f"calibrating the gyro: keep the robot still for {seconds:.1f} s")
    try:
        from robot.pi.hardware import PiHardware

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # gpiozero's factory fallback warnings; failures raise anyway
            hw = PiHardware.from_config(setup, pin_factory=pin_factory, bus_factory=bus_factory, sleep=sleep)
    except (HardwareError, ConfigError) as exc:
        out(f"error: {exc}")
        return EXIT_BAD_SETUP
    try:
        with hw:
            return _report(hw, setup, duration_s, out)
    except HardwareError as exc:
        out(f"error: {exc}")
        return EXIT_BAD_SETUP


def _describe(setup: PiSetup) -> str:
    ring = setup.pi.sonar_ring
    kind = "HC-SR04 on GPIO" if isinstance(ring, HcSr04RingConfig) else f"SRF02 on I2C bus {ring.bus}"
    return f"config {setup.path}: robot {setup.robot.name!r}, {len(ring.sensors)} sonars ({kind})"


def _report(hw: Any, setup: PiSetup, duration_s: float, out: Callable[[str], None]) -> int:
    robot = setup.robot
    if hw.imu is not None:
        imu, cal = hw.imu.imu, hw.gyro_calibration
        out(
            f"IMU: MPU-6050 on I2C bus {imu.bus_number} at {imu.address:#04x}, WHO_AM_I {imu.who_am_i:#04x}; "
            f"yaw rate bias {cal.yaw_bias_dps:+.3f} deg/s, noise {cal.yaw_std_dps:.3f} deg/s, "
            f"gravity {cal.gravity_up_g:+.2f} g along up axis"
        )
    else:
        out("IMU: disabled in the config")
    out(f"turn each wheel forward by hand: its count should rise by {robot.encoder_counts_per_rev} per revolution")
    n = len(robot.sonars)
    answered = [False] * n
    hw.read_imu()  # drop samples taken during start-up
    start_s = last_s = hw.now()
    imu_count = 0
    while True:
        ranges = hw.read_sonar_sweep().ranges_m
        for i, status in enumerate(hw.sonars.last_status):
            answered[i] = answered[i] or status != "no-response"
        counts = hw.read_encoders()
        samples = hw.read_imu()
        imu_count += len(samples)
        now_s = hw.now()
        rate_hz = len(samples) / (now_s - last_s) if now_s > last_s else 0.0
        last_s = now_s
        statuses = hw.sonars.last_status
        shown = " ".join(_range_text(r, s, robot.sonar.max_range_m) for r, s in zip(ranges, statuses, strict=True))
        yaw = f" yaw {samples[-1].gyro_z_rad_s:+.3f} rad/s" if samples else ""
        out(
            f"t={now_s - start_s:5.1f} s  sonars [m] {shown}  encoders L {counts.left:+d} R {counts.right:+d}"
            + (f"  IMU {rate_hz:5.1f} Hz{yaw}" if hw.imu is not None else "")
        )
        if now_s - start_s >= duration_s:
            break
    elapsed_s = hw.now() - start_s
    if hw.imu is not None:
        out(
            f"IMU: {imu_count} samples in {elapsed_s:.1f} s ({imu_count / max(elapsed_s, 1e-9):.1f} Hz, "
            f"configured {robot.imu.rate_hz:.0f} Hz)"
        )
    silent = [i for i in range(n) if not answered[i]]
    if silent:
        out(
            f"error: sonar{'s' if len(silent) > 1 else ''} {', '.join(map(str, silent))} never answered: "
            f"{_wiring_hint(setup, silent)}"
        )
        return EXIT_BAD_SETUP
    return EXIT_OK


def _range_text(range_m: float, status: str, max_range_m: float) -> str:
    if status == "no-response":
        return "  --"
    if status == "no-echo" or range_m >= max_range_m:
        return " max"
    return f"{range_m:4.2f}"


def _wiring_hint(setup: PiSetup, silent: list[int]) -> str:
    ring = setup.pi.sonar_ring
    if isinstance(ring, HcSr04RingConfig):
        parts = []
        for i in silent:
            s = ring.sensors[i]
            echo = s.echo_pin if s.echo_pin is not None else ring.shared_echo_pin
            parts.append(f"{i}: trigger GPIO{s.trigger_pin}, echo GPIO{echo}")
        return "check 5 V, ground and the pins (" + "; ".join(parts) + ")"
    addresses = ", ".join(f"{ring.sensors[i].address:#04x}" for i in silent)
    return f"check I2C bus {ring.bus} addresses {addresses}"
