"""PiHardware as a whole on mock pins and the fake bus: the protocol, motors, IMU, clock, close."""

from __future__ import annotations

import math
import time

import pytest

from robot.errors import HardwareError
from robot.hardware import Hardware
from robot.pi.hardware import PiHardware


def test_implements_the_hardware_protocol(robot_hw):
    assert isinstance(robot_hw, Hardware)


def test_forward_speed_drives_the_forward_pin(robot_hw, motor_states):
    robot_hw.set_wheel_speeds(0.125, -0.25)  # max wheel speed 0.25 m/s
    assert motor_states() == {"left": (0.5, 0.0), "right": (0.0, 1.0)}
    assert robot_hw.motors.duties == (0.5, -1.0)


def test_speeds_beyond_the_maximum_are_clipped(robot_hw, motor_states):
    robot_hw.set_wheel_speeds(1.0, -3.0)
    assert motor_states() == {"left": (1.0, 0.0), "right": (0.0, 1.0)}


def test_non_finite_speed_stops_and_raises(robot_hw, motor_states):
    robot_hw.set_wheel_speeds(0.2, 0.2)
    with pytest.raises(ValueError, match="finite"):
        robot_hw.set_wheel_speeds(math.nan, 0.1)
    assert motor_states() == {"left": (0.0, 0.0), "right": (0.0, 0.0)}


def test_stop_and_close_zero_the_motor_pins(robot_hw, motor_states):
    robot_hw.set_wheel_speeds(0.2, 0.1)
    robot_hw.stop()
    assert motor_states() == {"left": (0.0, 0.0), "right": (0.0, 0.0)}
    robot_hw.set_wheel_speeds(0.2, 0.1)
    robot_hw.close()
    robot_hw.close()  # idempotent
    assert motor_states() == {"left": (0.0, 0.0), "right": (0.0, 0.0)}
    with pytest.raises(HardwareError, match="closed"):
        robot_hw.read_encoders()


def test_pwm_frequency_comes_from_the_config(robot_hw, mock_factory):
    assert mock_factory.pin(12).frequency == 1000.0


def test_read_imu_returns_the_samples_since_the_last_call(robot_hw, fake_mpu, eventually):
    fake_mpu.set_raw(accel=(0, 0, 16384), gyro=(0, 0, 131 * 10))  # 10 deg/s counter-clockwise
    robot_hw.read_imu()
    samples = []
    assert eventually(lambda: samples.extend(robot_hw.read_imu()) or len(samples) >= 3)
    assert all(s.gyro_z_rad_s == pytest.approx(math.radians(10.0)) for s in samples[1:])
    times = [s.t_s for s in samples]
    assert times == sorted(times) and times[-1] <= robot_hw.now()


def test_start_up_calibrates_the_gyro(robot_hw):
    assert robot_hw.gyro_calibration.samples == 20
    assert robot_hw.gyro_calibration.gravity_up_g == pytest.approx(1.0)


def test_clock_is_monotonic_seconds_and_sleep_sleeps(robot_hw):
    before = time.monotonic()
    t0 = robot_hw.now()
    assert before <= t0 <= time.monotonic()
    robot_hw.sleep(0.02)
    assert robot_hw.now() - t0 >= 0.02


def test_every_hardware_call_reports_activity(robot_hw):
    calls = []
    robot_hw.add_activity_listener(lambda: calls.append(1))
    robot_hw.read_encoders()
    robot_hw.read_imu()
    robot_hw.set_wheel_speeds(0.0, 0.0)
    robot_hw.read_sonar_sweep()
    assert len(calls) == 3 + 1 + 8  # one per call, plus one per ping
    robot_hw.sleep(0.25)
    assert len(calls) >= 12 + 3  # long sleeps are sliced


def test_a_missing_imu_fails_cleanly_and_releases_the_pins(mock_factory, sonar_pins, i2c_bus, bus_factory, pi_setup):
    with pytest.raises(HardwareError, match="no device answers: IMU on I2C bus 1 at 0x68"):
        PiHardware.from_config(pi_setup, bus_factory=bus_factory, sleep=lambda s: None)
    assert i2c_bus.closed
    from gpiozero import Motor

    Motor(12, 13).close()  # nothing still holds the motor pins


def test_no_gpio_library_is_a_hardware_error(no_pin_factory, fake_mpu, bus_factory, pi_setup):
    with pytest.warns(Warning), pytest.raises(HardwareError, match=r"no GPIO pin factory .* install lgpio"):
        PiHardware.from_config(pi_setup, bus_factory=bus_factory, sleep=lambda s: None)


def test_open_loads_the_config_file(mock_factory, sonar_pins, fake_mpu, bus_factory, write_config):
    with PiHardware.open(write_config(), bus_factory=bus_factory, sleep=lambda s: None) as hw:
        assert hw.robot.name == "test-bot"
        assert len(hw.sonars) == 8
