"""check_hardware: the bring-up report and its exit codes."""

from __future__ import annotations

from robot.pi.check import check_hardware


def run_check(path, duration_s=0.0, **kwargs):
    lines: list[str] = []
    code = check_hardware(path, duration_s, out=lines.append, sleep=lambda s: None, **kwargs)
    return code, lines


def test_reports_imu_sonars_and_encoders(mock_factory, sonar_pins, fake_mpu, bus_factory, write_config):
    code, lines = run_check(write_config(), 0.1, bus_factory=bus_factory)
    text = "\n".join(lines)
    assert code == 0, text
    assert "robot 'test-bot', 8 sonars (HC-SR04 on GPIO)" in text
    assert "IMU: MPU-6050 on I2C bus 1 at 0x68, WHO_AM_I 0x68" in text
    assert "count should rise by 48 per revolution" in text
    sweep_lines = [line for line in lines if line.startswith("t=")]
    assert sweep_lines and "encoders L +0 R +0" in sweep_lines[0]
    shown = sweep_lines[0].split("sonars [m]")[1].split("encoders")[0].split()
    assert shown == ["0.50", "0.60", "0.70", "0.80", "0.90", "1.00", "1.10", "1.20"]
    assert any(line.startswith("IMU:") and "Hz" in line and "samples" in line for line in lines)
    assert not any(line.startswith("error") for line in lines)


def test_bad_config_is_one_error_line_and_exit_2(write_config, pi_toml):
    path = write_config(pi_toml.replace("a_pin = 5", "a_pin = 17"))
    code, lines = run_check(path)
    assert code == 2
    assert lines == [f"error: {path}: GPIO17 is used twice: sonar_ring.sensors[0].echo_pin and encoders.left.a_pin"]


def test_missing_imu_is_exit_2(mock_factory, sonar_pins, i2c_bus, bus_factory, write_config):
    code, lines = run_check(write_config(), bus_factory=bus_factory)
    assert code == 2
    assert lines[-1].startswith("error: no device answers: IMU on I2C bus 1 at 0x68")


def test_silent_sonar_is_exit_2_with_its_pins(mock_factory, fake_mpu, bus_factory, write_config):
    code, lines = run_check(write_config(), bus_factory=bus_factory)  # no emulated sonars at all
    assert code == 2
    assert lines[-1].startswith("error: sonars 0, 1, 2, 3, 4, 5, 6, 7 never answered")
    assert "0: trigger GPIO4, echo GPIO17" in lines[-1]
