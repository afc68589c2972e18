"""The one place the service creates a robot: the simulator, or the Raspberry Pi (imported only when chosen)."""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path
from typing import TYPE_CHECKING

from robot.hardware import Hardware
from robot.sim import SimRobot
from server.plan import RunPlan

if TYPE_CHECKING:
    from robot.pi.config import PiSetup
    from robot.pi.hardware import PiHardware

log = logging.getLogger("sonarslam.server")


def open_pi(setup: PiSetup) -> PiHardware:
    """The robot wired as ``setup`` says: GPIO through gpiozero's pin factory (lgpio on a Pi, or
    ``GPIOZERO_PIN_FACTORY``), I2C through smbus2, the system clock. Calibrates the gyro, so the robot
    must stand still. Raises HardwareError with a one-line reason when a device is missing."""
    from robot.pi.hardware import PiHardware

    return PiHardware.from_config(setup)


def open_hardware(plan: RunPlan, pi_config_file: Path | None = None) -> Hardware:
    """A fresh hardware backend for one run. Raises HardwareError (a SonarSlamError) when it cannot open.

    The Pi comes with its safety guard on until it is closed: the motors stop when the run thread
    stalls for ``safety.watchdog_timeout_s``, and closing (however the run ends) stops them first.
    SIGTERM/SIGINT belong to the service (see ``RunManager.halt_hardware``).
    """
    if plan.hardware == "sim":
        assert plan.world is not None
        return SimRobot(plan.world, plan.robot, plan.noise, seed=int(plan.options["seed"]), speed=plan.speed)
    if plan.hardware == "pi":
        from robot.pi.config import load_pi_setup

        setup = load_pi_setup(pi_config_file)
        return _guarded(open_pi(setup), setup.pi.safety.watchdog_timeout_s)
    raise ValueError(f"unknown hardware {plan.hardware!r}")


def _guarded(hw: PiHardware, watchdog_timeout_s: float) -> PiHardware:
    """Keep a safety guard on ``hw`` until it closes. Signal handlers stay out: they can only be installed
    on the main thread, and the service's own handlers halt the robot instead."""
    from robot.pi.safety import safe_hardware

    guard = contextlib.ExitStack()
    try:
        guard.enter_context(safe_hardware(hw, watchdog_timeout_s=watchdog_timeout_s, handle_signals=False))
    except BaseException:
        hw.close()
        raise
    hw.add_closer(guard.close)
    return hw


def halt(hw: Hardware, reason: str) -> bool:
    """Stop real motors at once and refuse further commands: the run's next hardware call raises
    HardwareError(reason). Safe from a signal handler. False for the simulator, which has no motors."""
    halt_now = getattr(hw, "halt", None)  # PiHardware.halt
    if not callable(halt_now):
        return False
    try:
        halt_now(reason)
    except Exception:  # keep going: the caller may have other robots to halt, and a shutdown to run
        log.exception("could not halt the hardware")
        return False
    return True


def set_speed(hw: Hardware, speed: float | None) -> bool:
    """Change the simulator's real-time factor (None = as fast as possible); False for real hardware."""
    if isinstance(hw, SimRobot):
        hw.set_speed(speed)
        return True
    return False
