"""Fixtures for the Pi backend: gpiozero mock pins, a fake I2C bus with register maps, test configs."""

from __future__ import annotations

import errno
import struct
import time
from collections import deque
from pathlib import Path

import pytest
from gpiozero import Device
from gpiozero.pins.mock import MockFactory, MockPin, MockPWMPin, MockTriggerPin
from pi_configs import ECHO_PINS, ENCODER_PINS, MOTOR_PINS, PI_TOML, ROBOT_TOML, SPEED_OF_SOUND_M_S, TRIGGER_PINS

from robot.pi.config import load_pi_setup


def echo_time_s(range_m: float) -> float:
    """HC-SR04 echo pulse width for a target at ``range_m``."""
    return 2.0 * range_m / SPEED_OF_SOUND_M_S


def no_sleep(_seconds: float) -> None:
    """Stands in for the drivers' long waits (calibration, I2C ranging) so tests stay fast."""


class RobotMockFactory(MockFactory):
    """A MockFactory whose motor pins are MockPWMPin and the rest MockPin.

    gpiozero refuses to hand out a pin as a different mock class than it was created with, and
    Motor(pwm=True) needs PWM pins, so the class is chosen per pin number.
    """

    def __init__(self, pwm_pins: set[int]) -> None:
        super().__init__()
        self.pwm_pins = pwm_pins

    def pin(self, name, pin_class=None, **kwargs):
        if pin_class is None and name in self.pwm_pins:
            pin_class = MockPWMPin
        return super().pin(name, pin_class=pin_class, **kwargs)


class ExactEchoPin(MockPin):
    """An echo pin whose falling edge is stamped exactly ``width_s`` after its rising edge.

    MockTriggerPin times the pulse with real sleeps; on a loaded machine a late wake-up of a few
    milliseconds is a metre of range. The drivers read edge timestamps, so stamping the edge
    exactly makes whole-robot tests deterministic while the pins still switch on real threads.
    """

    def __init__(self, factory, info, width_s: float | None = None) -> None:
        super().__init__(factory, info)
        self.width_s = width_s

    def _change_state(self, value):
        rise = self._last_change
        changed = super()._change_state(value)
        if changed and not value and self.width_s is not None:
            self._last_change = rise + self.width_s
        return changed


def emulate_hcsr04(factory, trigger: int, echo: int, range_m: float):
    """Wire an emulated HC-SR04 with an exactly timed echo for a target at ``range_m``."""
    width_s = echo_time_s(range_m)
    echo_pin = factory.pin(echo, pin_class=ExactEchoPin, width_s=width_s)
    return factory.pin(trigger, pin_class=MockTriggerPin, echo_pin=echo_pin, echo_time=width_s)


@pytest.fixture
def no_pin_factory(monkeypatch):
    """gpiozero with no pin factory to use or fall back on, as on a machine that is not a Pi."""
    try:
        import lgpio  # noqa: F401

        pytest.skip("a real pin factory is available here")
    except ImportError:
        pass
    monkeypatch.delenv("GPIOZERO_PIN_FACTORY", raising=False)
    monkeypatch.setattr(Device, "pin_factory", None)


@pytest.fixture
def hcsr04():
    """hcsr04(factory, trigger, echo, range_m) wires one emulated sensor."""
    return emulate_hcsr04


@pytest.fixture
def mock_factory():
    """Like gpiozero's own tests: a fresh mock factory as the default, restored afterwards."""
    saved = Device.pin_factory
    Device.pin_factory = RobotMockFactory({pin for pair in MOTOR_PINS.values() for pin in pair})
    try:
        yield Device.pin_factory
    finally:
        if Device.pin_factory is not None:
            Device.pin_factory.reset()
        Device.pin_factory = saved


@pytest.fixture
def sonar_pins(mock_factory):
    """Eight emulated HC-SR04s in mounting order, targets at 0.5 m, 0.6 m, ... 1.2 m."""
    return [
        emulate_hcsr04(mock_factory, trigger, echo, 0.5 + 0.1 * i)
        for i, (trigger, echo) in enumerate(zip(TRIGGER_PINS, ECHO_PINS, strict=True))
    ]


# -- fake I2C ---------------------------------------------------------------------------------


class FakeRegisterDevice:
    """An I2C device as a 256-byte register map; ``busy`` makes the next transactions fail like a
    device that does not acknowledge (OSError 121)."""

    def __init__(self) -> None:
        self.registers = bytearray(256)
        self.writes: list[tuple[int, int]] = []
        self.block_reads: list[tuple[int, int]] = []
        self.busy = 0

    def transaction(self) -> None:
        if self.busy > 0:
            self.busy -= 1
            raise OSError(errno.EREMOTEIO, "Remote I/O error")

    def read(self, register: int) -> int:
        return self.registers[register]

    def write(self, register: int, value: int) -> None:
        self.writes.append((register, value))
        self.registers[register] = value


class FakeMpu6050(FakeRegisterDevice):
    """Register map of an MPU-6050: asleep at power-up, data registers 0x3B..0x48 big-endian."""

    def __init__(self) -> None:
        super().__init__()
        self.registers[0x75] = 0x68
        self.registers[0x6B] = 0x40  # SLEEP
        self.queue: deque[tuple[tuple[int, int, int], int, tuple[int, int, int]]] = deque()
        self.set_raw(accel=(0, 0, 16384))  # level and still: +1 g on z

    def set_raw(self, accel=(0, 0, 0), temperature=0, gyro=(0, 0, 0)) -> None:
        self.registers[0x3B : 0x3B + 14] = struct.pack(">7h", *accel, temperature, *gyro)

    def read(self, register: int) -> int:
        if 0x3B <= register < 0x3B + 14 and self.registers[0x6B] & 0x40:
            return 0  # asleep: no data
        return super().read(register)

    def read_block(self, register: int, length: int) -> list[int]:
        if register == 0x3B and self.queue:
            accel, temperature, gyro = self.queue.popleft()
            self.set_raw(accel, temperature, gyro)
        return [self.read(register + i) for i in range(length)]


class FakeSrf02(FakeRegisterDevice):
    """An SRF02: register 0 reads the revision, a 0x51 command ranges in cm into registers 2-3 and
    leaves the device deaf to the bus for ``busy_after_command`` transactions."""

    def __init__(self, range_cm: int = 100, busy_after_command: int = 2) -> None:
        super().__init__()
        self.registers[0] = 6  # software revision
        self.registers[1] = 0x80
        self.range_cm = range_cm
        self.busy_after_command = busy_after_command
        self.commands = 0

    def read(self, register: int) -> int:
        return self.registers[register]

    def write(self, register: int, value: int) -> None:
        self.writes.append((register, value))
        if register == 0 and value == 0x51:
            self.commands += 1
            self.registers[2], self.registers[3] = self.range_cm >> 8, self.range_cm & 0xFF
            self.busy = self.busy_after_command

    def read_block(self, register: int, length: int) -> list[int]:
        return [self.read(register + i) for i in range(length)]


class FakeI2CBus:
    """Stands in for smbus2.SMBus: routes transactions to devices by address; absent ones NACK."""

    def __init__(self, number: int = 1) -> None:
        self.number = number
        self.devices: dict[int, FakeRegisterDevice] = {}
        self.log: list[tuple[str, int, int]] = []  # (operation, address, register)
        self.closed = False

    def attach(self, address: int, device: FakeRegisterDevice) -> FakeRegisterDevice:
        self.devices[address] = device
        return device

    def _device(self, op: str, address: int, register: int) -> FakeRegisterDevice:
        if self.closed:
            raise OSError(errno.EBADF, "Bad file descriptor")
        self.log.append((op, address, register))
        device = self.devices.get(address)
        if device is None:
            raise OSError(errno.EREMOTEIO, "Remote I/O error")
        device.transaction()
        return device

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        return self._device("read", i2c_addr, register).read(register)

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        self._device("write", i2c_addr, register).write(register, value)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        device = self._device("block", i2c_addr, register)
        device.block_reads.append((register, length))
        reader = getattr(device, "read_block", None)
        return reader(register, length) if reader else [device.read(register + i) for i in range(length)]

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def i2c_bus():
    return FakeI2CBus(1)


@pytest.fixture
def i2c_bus_class():
    """For tests that open a fresh fake bus per robot."""
    return FakeI2CBus


@pytest.fixture
def fake_mpu(i2c_bus):
    return i2c_bus.attach(0x68, FakeMpu6050())


@pytest.fixture
def bus_factory(i2c_bus):
    """What PiHardware.from_config calls to open bus n; records the numbers asked for."""

    def open_bus(number: int) -> FakeI2CBus:
        open_bus.opened.append(number)
        i2c_bus.number = number
        return i2c_bus

    open_bus.opened = []
    return open_bus


@pytest.fixture
def srf02_class():
    return FakeSrf02


@pytest.fixture
def mpu_class():
    return FakeMpu6050


# -- configs and a whole robot ----------------------------------------------------------------


@pytest.fixture
def write_config(tmp_path):
    """write_config(pi_toml=PI_TOML, robot_toml=ROBOT_TOML) -> path of a robot-pi.toml in tmp_path."""

    def write(pi_toml: str = PI_TOML, robot_toml: str = ROBOT_TOML) -> Path:
        (tmp_path / "robot.toml").write_text(robot_toml)
        path = tmp_path / "robot-pi.toml"
        path.write_text(pi_toml)
        return path

    return write


@pytest.fixture
def pi_setup(write_config):
    return load_pi_setup(write_config())


@pytest.fixture
def robot_hw(mock_factory, sonar_pins, fake_mpu, bus_factory, pi_setup):
    """A PiHardware on mock pins and the fake bus, IMU thread running."""
    from robot.pi.hardware import PiHardware

    hw = PiHardware.from_config(pi_setup, bus_factory=bus_factory, sleep=no_sleep)
    try:
        yield hw
    finally:
        hw.close()


def motor_pin_states(factory) -> dict[str, tuple[float, float]]:
    """(forward, backward) duty on each side's H-bridge inputs."""
    return {
        side: (float(factory.pin(fwd).state), float(factory.pin(bwd).state)) for side, (fwd, bwd) in MOTOR_PINS.items()
    }


@pytest.fixture
def motor_states(mock_factory):
    return lambda: motor_pin_states(mock_factory)


def wait_until(predicate, timeout_s: float = 2.0) -> bool:
    """Poll ``predicate`` until true; for behaviour that happens on another thread."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.002)
    return bool(predicate())


@pytest.fixture
def eventually():
    return wait_until


@pytest.fixture
def pi_toml() -> str:
    return PI_TOML


@pytest.fixture
def robot_toml() -> str:
    return ROBOT_TOML


@pytest.fixture
def echo_time():
    return echo_time_s


@pytest.fixture
def encoder_pins(mock_factory):
    """{'left': (A pin, B pin), 'right': (...)} as mock pins, to drive edges on."""
    return {side: (mock_factory.pin(a), mock_factory.pin(b)) for side, (a, b) in ENCODER_PINS.items()}


def turn(a_pin, b_pin, cycles: int, a_leads: bool = True) -> None:
    """Drive ``cycles`` full quadrature cycles (4 edges each); A leading B is forward for an unreversed encoder."""
    first, second = (a_pin, b_pin) if a_leads else (b_pin, a_pin)
    for _ in range(cycles):
        for pin in (first, second, first, second):
            if pin.state:
                pin.drive_low()
            else:
                pin.drive_high()


@pytest.fixture
def turn_wheel():
    return turn
