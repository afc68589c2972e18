"""Open-loop motor duties and dead-band compensation (``motors.min_duty``), read back from gpiozero's mock PWM pins."""

from __future__ import annotations

import math

import pytest
from pi_configs import robot_pi_toml

from robot.errors import ConfigError, HardwareError
from robot.pi.config import load_pi_setup
from robot.pi.hardware import PiHardware
from robot.pi.motors import DriveMotors, speed_to_duty

MAX_SPEED_M_S = 0.25  # max_wheel_speed_m_s of the test robot


@pytest.fixture
def deadband_hw(mock_factory, sonar_pins, fake_mpu, bus_factory, write_config):
    """``deadband_hw(min_duty)``: the test robot with that dead-band compensation."""
    opened: list[PiHardware] = []

    def open_robot(min_duty: float) -> PiHardware:
        setup = load_pi_setup(write_config(robot_pi_toml(motors=f"min_duty = {min_duty}")))
        hw = PiHardware.from_config(setup, bus_factory=bus_factory, sleep=lambda s: None, start_imu=False)
        opened.append(hw)
        return hw

    yield open_robot
    for hw in opened:
        hw.close()


def test_without_min_duty_the_duty_is_speed_over_max_speed():
    speeds = [0.0, -0.0, 1e-12, 0.01, 0.05, 0.0625, 0.1, 0.125, 0.2, 0.2499, 0.25, 0.3, 5.0, math.inf]
    for speed in speeds + [-s for s in speeds]:
        plain = min(1.0, max(-1.0, speed / MAX_SPEED_M_S))  # the map before min_duty existed
        assert speed_to_duty(speed, MAX_SPEED_M_S) == plain
        assert speed_to_duty(speed, MAX_SPEED_M_S, 0.0) == plain


def test_min_duty_lifts_every_nonzero_command_and_keeps_full_speed_at_full_duty():
    assert speed_to_duty(0.0, MAX_SPEED_M_S, 0.3) == 0.0
    assert speed_to_duty(1e-9, MAX_SPEED_M_S, 0.3) == pytest.approx(0.3)
    assert speed_to_duty(-1e-9, MAX_SPEED_M_S, 0.3) == pytest.approx(-0.3)
    assert speed_to_duty(0.125, MAX_SPEED_M_S, 0.3) == pytest.approx(0.65)  # half speed: half way from 0.3 to 1
    assert speed_to_duty(0.25, MAX_SPEED_M_S, 0.3) == 1.0
    assert speed_to_duty(-1.0, MAX_SPEED_M_S, 0.3) == -1.0  # still clipped


def test_min_duty_reaches_the_h_bridge_pins(deadband_hw, motor_states):
    hw = deadband_hw(0.3)
    assert hw.motors.min_duty == 0.3
    hw.set_wheel_speeds(0.125, -0.25)
    left, right = motor_states()["left"], motor_states()["right"]
    assert left == (pytest.approx(0.65), 0.0) and right == (0.0, 1.0)
    hw.set_wheel_speeds(0.0025, -0.0025)  # 1 % of full speed: just above the dead-band, not lost in it
    left, right = motor_states()["left"], motor_states()["right"]
    assert left == (pytest.approx(0.307), 0.0) and right == (0.0, pytest.approx(0.307))
    hw.set_wheel_speeds(0.0, 0.1)
    left, right = motor_states()["left"], motor_states()["right"]
    assert left == (0.0, 0.0) and right == (pytest.approx(0.58), 0.0)
    hw.stop()
    assert motor_states() == {"left": (0.0, 0.0), "right": (0.0, 0.0)}


def test_default_min_duty_drives_the_pins_as_before(deadband_hw, motor_states):
    hw = deadband_hw(0.0)
    hw.set_wheel_speeds(0.0025, -0.125)
    assert motor_states() == {"left": (0.0025 / MAX_SPEED_M_S, 0.0), "right": (0.0, 0.5)}


@pytest.mark.parametrize("value", ["-0.1", "1.0", "1.5", "nan"])
def test_min_duty_is_validated(write_config, value):
    path = write_config(robot_pi_toml(motors=f"min_duty = {value}"))
    with pytest.raises(ConfigError, match=r"robot-pi\.toml: motors\.min_duty: "):
        load_pi_setup(path)


def test_drive_motors_refuse_a_min_duty_outside_0_to_1(mock_factory):
    from robot.pi.config import MotorPins

    left, right = MotorPins(forward_pin=12, backward_pin=13), MotorPins(forward_pin=18, backward_pin=19)
    with pytest.raises(ValueError, match="min_duty"):
        DriveMotors(left, right, max_wheel_speed_m_s=MAX_SPEED_M_S, min_duty=1.0)


def test_shipped_config_has_no_dead_band_compensation():
    assert load_pi_setup().pi.motors.min_duty == 0.0


def test_pins_without_pwm_are_a_one_line_hardware_error(fake_mpu, bus_factory, write_config):
    from gpiozero import Device
    from gpiozero.pins.mock import MockFactory

    saved, Device.pin_factory = Device.pin_factory, MockFactory()  # plain mock pins, as GPIOZERO_PIN_FACTORY=mock
    try:
        with pytest.raises(HardwareError, match=r"motors: the pin factory cannot drive PWM .* GPIOZERO_MOCK_PIN_CLASS"):
            PiHardware.from_config(load_pi_setup(write_config()), bus_factory=bus_factory, sleep=lambda s: None)
    finally:
        Device.pin_factory.reset()
        Device.pin_factory = saved
