"""The one place the service creates a robot: the simulator, or the Raspberry Pi (imported only when chosen)."""

from __future__ import annotations

from pathlib import Path

from robot.hardware import Hardware
from robot.sim import SimRobot
from server.plan import RunPlan


def open_hardware(plan: RunPlan, pi_config_file: Path | None = None) -> Hardware:
    """A fresh hardware backend for one run. Raises HardwareError (a SonarSlamError) when it cannot open."""
    if plan.hardware == "sim":
        assert plan.world is not None
        return SimRobot(plan.world, plan.robot, plan.noise, seed=int(plan.options["seed"]), speed=plan.speed)
    if plan.hardware == "pi":
        # TODO(pi): the PiHardware constructor is not final; this follows robot/pi/hardware.py as of today
        # (load the wiring, open every device, calibrate the gyro). Only "sim" is tested here.
        from robot.pi import PiHardware
        from robot.pi.config import load_pi_setup

        return PiHardware.from_config(load_pi_setup(pi_config_file))
    raise ValueError(f"unknown hardware {plan.hardware!r}")


def set_speed(hw: Hardware, speed: float | None) -> bool:
    """Change the simulator's real-time factor (None = as fast as possible); False for real hardware."""
    if isinstance(hw, SimRobot):
        hw.set_speed(speed)
        return True
    return False
