"""Sim in the loop: the simulator's physics behind the Pi backend's mock pins and fake I2C bus.

``SimBridge`` owns a simulated clock shared by ``PiHardware`` (its ``clock``/``sleep`` arguments)
and a ``SimRobot``. Whenever the Pi side sleeps, the bridge

* reads the wheel command back from the H-bridge ``MockPWMPin`` duties (forward - backward),
* advances the simulator by the same time with that command,
* turns the simulator's encoder count changes into quadrature edges on the mock encoder pins,
* writes each of the simulator's gyro samples into the fake MPU-6050's registers (deg/s x 131 on
  the chip axis mounted "up") and samples it through ``ImuSampler.poll`` at the sample's time,

and each fake SRF02 answers a ranging command with the simulator's range for its sonar, in cm, at
the moment of the command. Nothing here touches ``robot/``: the Pi drivers run unmodified.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from robot.pi.config import PiSetup, Srf02RingConfig
from robot.sim import SimRobot

GYRO_LSB_PER_DPS = 131.0
ACCEL_LSB_PER_G = 16384
INT16_MAX = 32767

# Quadrature state (A << 1) | B, stepped one edge at a time; A leading B (this order) is forward
# for an encoder mounted unreversed (see robot/pi/encoders.py).
FORWARD_SEQUENCE = (0b00, 0b10, 0b11, 0b01)


def _axis(name: str) -> tuple[int, int]:
    """'-y' -> (chip index 1, sign -1)."""
    return "xyz".index(name[1]), (-1 if name[0] == "-" else 1)


def sim_srf02(srf02_class: Any, bridge: SimBridge, index: int) -> Any:
    """A fake SRF02 (conftest's ``FakeSrf02``) whose ranging command measures the simulator's range
    for sonar ``index`` at the moment the command arrives."""
    device = srf02_class(range_cm=0, busy_after_command=1)  # deaf for one transaction, like the real one
    plain_write = device.write

    def write(register: int, value: int) -> None:
        if register == 0 and value == 0x51:
            device.range_cm = bridge.range_cm(index)
        plain_write(register, value)

    device.write = write
    return device


class QuadratureOutput:
    """Drives an encoder's A/B mock pins edge by edge to follow a wheel's count."""

    def __init__(self, a_pin: Any, b_pin: Any, reversed: bool) -> None:
        self.a_pin, self.b_pin = a_pin, b_pin
        self.sign = -1 if reversed else 1
        state = (int(bool(a_pin.state)) << 1) | int(bool(b_pin.state))
        self.phase = FORWARD_SEQUENCE.index(state)
        self.edges = 0

    def step(self, counts: int) -> None:
        """Emit ``|counts|`` edges, forward for positive counts (as the wheel sees it)."""
        direction = 1 if counts * self.sign > 0 else -1  # pin-level direction
        for _ in range(abs(counts)):
            old = FORWARD_SEQUENCE[self.phase]
            self.phase = (self.phase + direction) % 4
            new = FORWARD_SEQUENCE[self.phase]
            pin, level = (self.a_pin, new >> 1) if (old ^ new) & 0b10 else (self.b_pin, new & 1)
            if level:
                pin.drive_high()
            else:
                pin.drive_low()
            self.edges += 1


class SimBridge:
    """The shared simulated clock and the glue between ``SimRobot`` and the Pi backend's fakes."""

    def __init__(
        self, sim: SimRobot, setup: PiSetup, factory: Any, *, bus: Any, mpu_class: Any, srf02_class: Any
    ) -> None:
        self.sim = sim
        self.setup = setup
        self.factory = factory
        self.t = sim.now()
        self.hw: Any = None  # the PiHardware, once built; its IMU sampler is polled per gyro sample
        pi = setup.pi
        self.max_speed = setup.robot.max_wheel_speed_m_s
        self.motor_pins = [
            (factory.pin(m.forward_pin), factory.pin(m.backward_pin)) for m in (pi.motors.left, pi.motors.right)
        ]
        self.bus = bus  # conftest's FakeI2CBus
        self.bus.number = pi.imu.bus
        self.mpu = mpu_class()
        self._up = _axis(pi.imu.up_axis)
        accel = [0, 0, 0]
        accel[self._up[0]] = self._up[1] * ACCEL_LSB_PER_G  # level: +1 g along the mounted up axis
        self._accel = (accel[0], accel[1], accel[2])
        self.mpu.set_raw(accel=self._accel)
        self.bus.attach(pi.imu.address, self.mpu)
        ring = pi.sonar_ring
        assert isinstance(ring, Srf02RingConfig), "the bridge emulates SRF02 sonars on the fake bus"
        assert ring.bus == pi.imu.bus, "one fake bus carries both the sonars and the IMU"
        self.sonars = [self.bus.attach(s.address, sim_srf02(srf02_class, self, i)) for i, s in enumerate(ring.sensors)]
        self._encoders: list[QuadratureOutput] | None = None
        self._pushed = (0, 0)  # simulator counts already sent as edges
        self.gyro_samples = 0
        self.saturated_samples = 0
        self.commands: list[tuple[float, float]] = []  # distinct wheel commands seen on the pins

    # -- what PiHardware.from_config gets -----------------------------------------------------
    def now(self) -> float:
        return self.t

    def open_bus(self, number: int) -> Any:
        assert number == self.bus.number, f"no fake I2C bus {number}"
        return self.bus

    def sleep(self, duration_s: float) -> None:
        if duration_s <= 0.0:
            return
        left, right = self.wheel_command()
        if not self.commands or self.commands[-1] != (left, right):
            self.commands.append((left, right))
        self.sim.set_wheel_speeds(left, right)
        self.sim.sleep(duration_s)
        self._sync_encoders()
        self._sync_imu()
        self.t = self.sim.now()

    # -- pins and registers -------------------------------------------------------------------
    def wheel_command(self) -> tuple[float, float]:
        """Rim speeds [m/s] as the H-bridges drive them: (forward duty - backward duty) x max speed."""
        left, right = ((float(fwd.state) - float(bwd.state)) * self.max_speed for fwd, bwd in self.motor_pins)
        return left, right

    def attach_encoders(self) -> None:
        """Call once the encoders exist (after ``from_config``): their pins now have handlers."""
        enc = self.setup.pi.encoders
        self._encoders = [
            QuadratureOutput(self.factory.pin(p.a_pin), self.factory.pin(p.b_pin), p.reversed)
            for p in (enc.left, enc.right)
        ]
        counts = self.sim.read_encoders()
        self._pushed = (counts.left, counts.right)

    def _sync_encoders(self) -> None:
        if self._encoders is None:
            return
        counts = self.sim.read_encoders()
        for output, now, before in zip(self._encoders, (counts.left, counts.right), self._pushed, strict=True):
            output.step(now - before)
        self._pushed = (counts.left, counts.right)

    def _sync_imu(self) -> None:
        for sample in self.sim.read_imu():
            raw = math.degrees(sample.gyro_z_rad_s) * GYRO_LSB_PER_DPS
            if abs(raw) > INT16_MAX:
                self.saturated_samples += 1
            gyro = [0, 0, 0]
            gyro[self._up[0]] = self._up[1] * int(max(-INT16_MAX - 1, min(INT16_MAX, round(raw))))
            self.mpu.set_raw(accel=self._accel, gyro=(gyro[0], gyro[1], gyro[2]))
            self.gyro_samples += 1
            if self.hw is not None and self.hw.imu is not None:
                self.t = sample.t_s  # the sampler stamps the read with the clock: the sample's time
                self.hw.imu.poll()

    def range_cm(self, index: int) -> int:
        """The simulator's range for sonar ``index`` now, as the SRF02 reports it (0 = no echo)."""
        range_m = float(self.sim._ping(np.array([index]))[0])
        if range_m >= self.setup.robot.sonar.max_range_m:
            return 0
        return int(round(range_m * 100.0))
