"""The simulator: the only code that knows the world and the true pose."""

from robot.sim.simulator import SimRobot

__all__ = ["SimRobot"]
