"""One builder for the robot-pi.toml files the Pi tests load: the test wiring, any section swappable.

Every test robot has the same motors and encoders (the pins of ``config/robot-pi.toml``); what differs
is the robot file, the sonar ring (HC-SR04 on GPIO or SRF02 on I2C) and the IMU, safety and motor
settings. Tests that edit the text (``.replace``) rely on the layout below, so keep it stable.
"""

from __future__ import annotations

from collections.abc import Iterable

from robot.config import DEFAULT_ROBOT_FILE

SPEED_OF_SOUND_M_S = 343.0
TRIGGER_PINS = (4, 27, 23, 25, 21, 8, 10, 14)
ECHO_PINS = (17, 22, 24, 26, 7, 9, 11, 15)
SRF02_ADDRESSES = tuple(range(0x70, 0x78))
MOTOR_PINS = {"left": (12, 13), "right": (18, 19)}  # (forward, backward)
ENCODER_PINS = {"left": (5, 6), "right": (16, 20)}  # (A, B)

ROBOT_TOML = """
[robot]
name = "test-bot"
max_wheel_speed_m_s = 0.25
encoder_counts_per_rev = 48
[sonar]
max_range_m = 4.0
ping_interval_s = 0.0
firing_order = [0, 4, 2, 6, 1, 5, 3, 7]
[imu]
rate_hz = 200.0
"""


def hcsr04_ring(speed_of_sound_m_s: float = SPEED_OF_SOUND_M_S) -> str:
    """Eight HC-SR04s in mounting order, each with its own echo pin."""
    sensors = ",\n".join(
        f"  {{ trigger_pin = {t}, echo_pin = {e} }}" for t, e in zip(TRIGGER_PINS, ECHO_PINS, strict=True)
    )
    return f'[sonar_ring]\nkind = "hcsr04"\nspeed_of_sound_m_s = {speed_of_sound_m_s}\nsensors = [\n{sensors}\n]\n'


def srf02_ring(addresses: Iterable[int | str] = SRF02_ADDRESSES, bus: int = 1) -> str:
    """SRF02s on one I2C bus in mounting order; an address may be given as text (``"0xE0"``) to test the checks."""
    sensors = ", ".join(f"{{ address = {a if isinstance(a, str) else f'{a:#04x}'} }}" for a in addresses)
    return f'[sonar_ring]\nkind = "srf02"\nbus = {bus}\nsensors = [{sensors}]\n'


def _table(name: str, body: str | None) -> str:
    if body is None:
        return ""
    return f"[{name}]\n{body.strip()}\n" if body.strip() else f"[{name}]\n"


def robot_pi_toml(
    *,
    robot_file: str = "robot.toml",
    sonar_ring: str | None = None,
    motors: str | None = None,
    imu: str | None = "calibration_samples = 20",
    safety: str | None = "watchdog_timeout_s = 0.5",
) -> str:
    """A robot-pi.toml: ``sonar_ring`` is a whole ``[sonar_ring]`` table (default :func:`hcsr04_ring`);
    ``motors``, ``imu`` and ``safety`` are the bodies of those tables, None to leave the table out."""
    ring = hcsr04_ring() if sonar_ring is None else sonar_ring
    (left_fwd, left_bwd), (right_fwd, right_bwd) = MOTOR_PINS["left"], MOTOR_PINS["right"]
    (left_a, left_b), (right_a, right_b) = ENCODER_PINS["left"], ENCODER_PINS["right"]
    return (
        f'\nrobot_file = "{robot_file}"\n'
        f"{ring}"
        f"{_table('motors', motors)}"
        f"[motors.left]\nforward_pin = {left_fwd}\nbackward_pin = {left_bwd}\n"
        f"[motors.right]\nforward_pin = {right_fwd}\nbackward_pin = {right_bwd}\n"
        '[encoders]\npulses_per_rev = 12\ndecoding = "x4"\n'
        f"[encoders.left]\na_pin = {left_a}\nb_pin = {left_b}\n"
        f"[encoders.right]\na_pin = {right_a}\nb_pin = {right_b}\nreversed = true\n"
        f"{_table('imu', imu)}"
        f"{_table('safety', safety)}"
    )


PI_TOML = robot_pi_toml()

UPRIGHT = 'forward_axis = "+x"\nleft_axis = "+y"\nup_axis = "+z"'
UPSIDE_DOWN = 'forward_axis = "+x"\nleft_axis = "-y"\nup_axis = "-z"'  # component side down


def sim_pi_toml(imu_axes: str = UPRIGHT) -> str:
    """The paper robot (config/robot.toml) with SRF02 sonars and the IMU on I2C bus 1, as ``SimBridge`` emulates."""
    return robot_pi_toml(
        robot_file=DEFAULT_ROBOT_FILE.as_posix(),
        sonar_ring=srf02_ring(bus=1),
        imu=f"bus = 1\ncalibration_samples = 100\n{imu_axes}",
        safety=None,
    )
