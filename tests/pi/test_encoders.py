"""Wheel encoders: quadrature decoding, mock-pin edges, signs and counts per revolution."""

from __future__ import annotations

import pytest

from robot.pi.encoders import QuadratureDecoder, WheelEncoder

FORWARD = [(1, 0), (1, 1), (0, 1), (0, 0)]  # (A, B) after each edge, from 00, A leading


def run(decoder: QuadratureDecoder, states) -> int:
    total = 0
    for a, b in states:
        if a != decoder.a:
            total += decoder.on_a(a)
        if decoder.b is not None and b != decoder.b:
            total += decoder.on_b(b)
    return total


@pytest.mark.parametrize(("decoding", "per_cycle"), [("x4", 4), ("x2", 2), ("x1", 1)])
def test_decoding_counts_per_quadrature_cycle(decoding, per_cycle):
    assert run(QuadratureDecoder(decoding, 0, 0), FORWARD * 3) == 3 * per_cycle
    backward = [(a, b) for a, b in reversed(FORWARD[:-1])] + [(0, 0)]
    assert run(QuadratureDecoder(decoding, 0, 0), backward * 3) == -3 * per_cycle


def test_a_repeated_level_means_a_missed_edge():
    decoder = QuadratureDecoder("x4", 0, 0)
    assert decoder.on_a(1) == 1
    assert decoder.on_a(1) == 0  # the falling edge in between was lost
    assert decoder.missed == 1


def test_single_channel_takes_the_sign_of_the_command():
    decoder = QuadratureDecoder("x2", 0, None)
    decoder.direction = -1
    assert decoder.on_a(1) + decoder.on_a(0) == -2


def test_x4_needs_channel_b():
    with pytest.raises(ValueError, match="x4 decoding needs channel B"):
        QuadratureDecoder("x4", 0, None)


def test_one_forward_wheel_revolution_is_48_counts(mock_factory, encoder_pins, turn_wheel):
    encoder = WheelEncoder(5, 6, decoding="x4")
    try:
        a, b = encoder_pins["left"]
        turn_wheel(a, b, 12)  # 12 pulses per revolution
        assert encoder.count == 48
        turn_wheel(a, b, 3, a_leads=False)
        assert encoder.count == 48 - 12
        assert encoder.missed_edges == 0
    finally:
        encoder.close()


def test_reversed_encoder_counts_forward_as_positive(mock_factory, encoder_pins, turn_wheel):
    encoder = WheelEncoder(16, 20, decoding="x4", reversed=True)
    try:
        a, b = encoder_pins["right"]
        turn_wheel(a, b, 12, a_leads=False)  # mirrored wheel: B leads A when it drives forward
        assert encoder.count == 48
    finally:
        encoder.close()


def test_hardware_counts_both_wheels_forward_positive(robot_hw, encoder_pins, turn_wheel):
    turn_wheel(*encoder_pins["left"], 12)
    turn_wheel(*encoder_pins["right"], 6, a_leads=False)  # right encoder is reversed in the config
    counts = robot_hw.read_encoders()
    assert (counts.left, counts.right) == (48, 24)
    assert counts.t_s <= robot_hw.now()


def test_single_channel_direction_follows_the_motor_command(
    mock_factory, sonar_pins, fake_mpu, bus_factory, write_config, pi_toml, encoder_pins
):
    from robot.pi.config import load_pi_setup
    from robot.pi.hardware import PiHardware

    toml = pi_toml.replace("b_pin = 6\n", "").replace("b_pin = 20\n", "")
    toml = toml.replace("pulses_per_rev = 12", "pulses_per_rev = 24").replace('decoding = "x4"', 'decoding = "x2"')
    with PiHardware.from_config(load_pi_setup(write_config(toml)), bus_factory=bus_factory, sleep=lambda s: None) as hw:
        left_a = encoder_pins["left"][0]
        hw.set_wheel_speeds(-0.1, 0.1)
        left_a.drive_low()
        left_a.drive_high()
        hw.set_wheel_speeds(0.0, 0.0)  # coasting keeps the last direction
        left_a.drive_low()
        assert hw.read_encoders().left == -3
        hw.set_wheel_speeds(0.2, 0.0)
        left_a.drive_high()
        assert hw.read_encoders().left == -2
