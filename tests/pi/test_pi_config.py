"""robot-pi.toml validation: pins, I2C addresses, IMU axes and consistency with the robot file."""

from __future__ import annotations

import re

import pytest
from pi_configs import SRF02_ADDRESSES, robot_pi_toml, srf02_ring

from robot.config import load_robot_config
from robot.errors import ConfigError
from robot.pi.config import DEFAULT_PI_FILE, load_pi_setup


def test_shipped_config_matches_the_robot():
    setup = load_pi_setup()
    robot, _ = load_robot_config()
    assert setup.path == DEFAULT_PI_FILE
    assert setup.robot == robot
    assert len(setup.pi.sonar_ring.sensors) == len(robot.sonars) == 8
    assert setup.pi.encoders.counts_per_rev == robot.encoder_counts_per_rev == 48
    pins = [pin for pin, _ in setup.pi.pin_uses()]
    assert len(pins) == len(set(pins))


def test_loads_and_resolves_the_robot_file_next_to_it(write_config):
    setup = load_pi_setup(write_config())
    assert setup.robot.name == "test-bot"
    assert setup.pi.imu.address == 0x68
    assert setup.pi.sonar_ring.kind == "hcsr04"


def test_a_pin_used_twice_names_both_uses_and_the_file(write_config, pi_toml):
    path = write_config(pi_toml.replace("a_pin = 5", "a_pin = 17"))  # 17 is sonar 0's echo
    with pytest.raises(ConfigError) as err:
        load_pi_setup(path)
    message = str(err.value)
    assert message.startswith(str(path))
    assert "GPIO17 is used twice" in message
    assert "sonar_ring.sensors[0].echo_pin" in message and "encoders.left.a_pin" in message


def test_i2c_bus_pins_count_as_used(write_config, pi_toml):
    path = write_config(pi_toml.replace("trigger_pin = 4,", "trigger_pin = 2,"))
    expected = "GPIO2 is used twice: sonar_ring.sensors[0].trigger_pin and I2C bus 1 SDA"
    with pytest.raises(ConfigError, match=re.escape(expected)):
        load_pi_setup(path)


def test_i2c_pins_are_free_without_i2c_devices(write_config, pi_toml):
    toml = pi_toml.replace("trigger_pin = 4,", "trigger_pin = 2,").replace(
        "calibration_samples = 20", "enabled = false"
    )
    assert load_pi_setup(write_config(toml)).pi.imu.enabled is False


def _with_srf02(last_address: str) -> str:
    return robot_pi_toml(sonar_ring=srf02_ring([*SRF02_ADDRESSES[:-1], last_address]))


def test_srf02_ring_loads(write_config):
    setup = load_pi_setup(write_config(_with_srf02("0x7F")))
    assert [s.address for s in setup.pi.sonar_ring.sensors][-1] == 0x7F


@pytest.mark.parametrize(
    ("address", "expected"),
    [
        ("0xE0", "0xe0 is the 8-bit form; use the 7-bit address 0x70"),
        ("0x50", "SRF02/SRF08 I2C address 0x50 is outside 0x70-0x7f"),
        ("0x70", "I2C address 0x70 is used by sensors[0] and sensors[7]"),
    ],
)
def test_srf02_addresses_are_checked(write_config, address, expected):
    with pytest.raises(ConfigError, match=expected.replace("[", r"\[").replace("]", r"\]")):
        load_pi_setup(write_config(_with_srf02(address)))


def test_imu_address_is_checked(write_config, pi_toml):
    path = write_config(pi_toml.replace("calibration_samples = 20", "address = 0x70"))
    with pytest.raises(ConfigError, match=re.escape("imu.address: MPU-6050 I2C address 0x70 is outside 0x68-0x69")):
        load_pi_setup(path)


def test_imu_axes_must_form_a_right_handed_frame(write_config, pi_toml):
    path = write_config(pi_toml.replace("calibration_samples = 20", 'up_axis = "-z"'))
    with pytest.raises(ConfigError, match=r"not a right-handed frame; .* up_axis must be '\+z'"):
        load_pi_setup(path)


def test_upside_down_mounting_is_accepted(write_config, pi_toml):
    toml = pi_toml.replace("calibration_samples = 20", 'left_axis = "-y"\nup_axis = "-z"')
    assert load_pi_setup(write_config(toml)).pi.imu.up_axis == "-z"


def test_encoder_counts_must_match_the_robot(write_config, pi_toml):
    path = write_config(pi_toml.replace("pulses_per_rev = 12", "pulses_per_rev = 16"))
    expected = "16 pulses/rev x 4 (x4) = 64 counts/rev, but encoder_counts_per_rev is 48"
    with pytest.raises(ConfigError, match=re.escape(expected)):
        load_pi_setup(path)


def test_single_channel_encoders_need_x1_or_x2(write_config, pi_toml):
    path = write_config(pi_toml.replace("b_pin = 6\n", ""))
    with pytest.raises(ConfigError, match="left: x4 decoding needs b_pin"):
        load_pi_setup(path)


def test_sonar_count_must_match_the_mounts(write_config, pi_toml):
    toml = pi_toml.replace("  { trigger_pin = 14, echo_pin = 15 }", "").replace("echo_pin = 11 },", "echo_pin = 11 }")
    path = write_config(toml)
    with pytest.raises(ConfigError, match="sonar_ring lists 7 sensors but the robot has 8 sonars"):
        load_pi_setup(path)


def test_shared_echo_pin(write_config, pi_toml):
    toml = pi_toml
    for echo in (17, 22, 24, 26, 7, 9, 11, 15):
        toml = toml.replace(f", echo_pin = {echo} }}", " }")
    toml = toml.replace('kind = "hcsr04"', 'kind = "hcsr04"\nshared_echo_pin = 17')
    ring = load_pi_setup(write_config(toml)).pi.sonar_ring
    assert ring.shared_echo_pin == 17 and all(s.echo_pin is None for s in ring.sensors)


def test_missing_echo_pin_is_explained(write_config, pi_toml):
    path = write_config(pi_toml.replace(", echo_pin = 22 }", " }"))
    with pytest.raises(ConfigError, match=r"sensors\[1\] has no echo_pin and there is no shared_echo_pin"):
        load_pi_setup(path)


def test_unknown_keys_and_missing_files_are_config_errors(write_config, pi_toml, tmp_path):
    with pytest.raises(ConfigError, match="motor_typo"):
        load_pi_setup(write_config(pi_toml + "\nmotor_typo = 1\n"))
    with pytest.raises(ConfigError, match="file not found"):
        load_pi_setup(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_pi_setup(write_config("[motors"))
    with pytest.raises(ConfigError, match=re.escape("missing/robot.toml: file not found")):
        load_pi_setup(write_config(pi_toml.replace('robot_file = "robot.toml"', 'robot_file = "missing/robot.toml"')))
