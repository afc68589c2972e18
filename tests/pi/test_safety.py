"""Every way a run can end stops the motors: normal exit, exception, SIGTERM, SIGINT, a stalled loop."""

from __future__ import annotations

import os
import signal
import time

import pytest

from robot.errors import HardwareError
from robot.pi.safety import Watchdog, safe_hardware

STOPPED = {"left": (0.0, 0.0), "right": (0.0, 0.0)}


def test_leaving_the_block_stops_the_motors(robot_hw, motor_states):
    with safe_hardware(robot_hw):
        robot_hw.set_wheel_speeds(0.2, 0.2)
        assert motor_states() != STOPPED
    assert motor_states() == STOPPED


def test_an_exception_in_the_loop_stops_the_motors(robot_hw, motor_states):
    with pytest.raises(RuntimeError, match="planner bug"), safe_hardware(robot_hw) as guard:
        robot_hw.set_wheel_speeds(0.2, -0.2)
        raise RuntimeError("planner bug")
    assert motor_states() == STOPPED
    assert guard.stop_reason == "stopped by RuntimeError: planner bug"


def test_sigterm_stops_the_motors_and_ends_the_run(robot_hw, motor_states):
    previous = signal.getsignal(signal.SIGTERM)
    with pytest.raises(SystemExit) as exit_info, safe_hardware(robot_hw) as guard:
        robot_hw.set_wheel_speeds(0.2, 0.2)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(1.0)  # the handler interrupts this
    assert exit_info.value.code == 128 + signal.SIGTERM
    assert motor_states() == STOPPED
    assert guard.stop_reason == "stopped by SIGTERM"
    assert signal.getsignal(signal.SIGTERM) == previous  # handler restored
    with pytest.raises(HardwareError, match="stopped by SIGTERM"):
        robot_hw.set_wheel_speeds(0.1, 0.1)  # halted: no more commands
    assert motor_states() == STOPPED


def test_sigint_handler_stops_the_motors(robot_hw, motor_states):
    # Python's own handler before the guard's, as in a foreground process (a shell starts background
    # jobs with SIGINT ignored, and the guard then keeps ignoring it after halting).
    outer = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt), safe_hardware(robot_hw):
            robot_hw.set_wheel_speeds(-0.2, 0.2)
            handler = signal.getsignal(signal.SIGINT)
            handler(signal.SIGINT, None)
    finally:
        signal.signal(signal.SIGINT, outer)
    assert motor_states() == STOPPED


def test_a_stalled_loop_trips_the_watchdog(robot_hw, motor_states, eventually):
    with safe_hardware(robot_hw, watchdog_timeout_s=0.1) as guard:
        robot_hw.set_wheel_speeds(0.2, 0.2)
        assert eventually(lambda: motor_states() == STOPPED)  # nothing feeds it: stalled
        assert guard.watchdog.trips == 1
        robot_hw.set_wheel_speeds(0.1, 0.1)  # the loop is back: commands work again
        assert motor_states() != STOPPED
        assert eventually(lambda: guard.watchdog.trips == 2)


def test_a_live_loop_keeps_the_motors_running(robot_hw, motor_states):
    with safe_hardware(robot_hw, watchdog_timeout_s=0.2) as guard:
        robot_hw.set_wheel_speeds(0.2, 0.2)
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            robot_hw.read_encoders()  # any hardware call feeds the watchdog
            time.sleep(0.01)
        assert guard.watchdog.trips == 0
        assert motor_states() != STOPPED


class BareHardware:
    """Hardware without activity listeners or halt (like a simulator)."""

    def __init__(self) -> None:
        self.stops = 0

    def stop(self) -> None:
        self.stops += 1


def test_guard_works_with_any_hardware_via_explicit_feed(eventually):
    hw = BareHardware()
    with safe_hardware(hw, watchdog_timeout_s=0.1, handle_signals=False) as guard:  # type: ignore[arg-type]
        end = time.monotonic() + 0.3
        while time.monotonic() < end:
            guard.feed()
            time.sleep(0.01)
        assert hw.stops == 0
        assert eventually(lambda: hw.stops == 1)
    assert hw.stops == 2  # and once more on exit


def test_watchdog_fires_once_per_stall_and_rearms_on_feed(eventually):
    fired = []
    with Watchdog(0.05, lambda: fired.append(1)) as dog:
        assert eventually(lambda: len(fired) == 1)
        time.sleep(0.1)
        assert len(fired) == 1 and dog.expired
        dog.feed()
        assert not dog.expired
        assert eventually(lambda: len(fired) == 2)
