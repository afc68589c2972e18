"""MPU-6050 IMU on I2C: set-up, gyro bias calibration, unit conversion and a background sampler."""

from __future__ import annotations

import logging
import math
import struct
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from robot.errors import HardwareError
from robot.hardware import ImuSample
from robot.pi.config import axis_vector
from robot.pi.i2c import I2cBus

log = logging.getLogger(__name__)

# Register map (RM-MPU-6000A).
SMPLRT_DIV = 0x19
CONFIG = 0x1A
GYRO_CONFIG = 0x1B
ACCEL_CONFIG = 0x1C
ACCEL_XOUT_H = 0x3B  # 14 bytes: accel x y z, temperature, gyro x y z, big-endian int16
PWR_MGMT_1 = 0x6B
WHO_AM_I = 0x75
WHO_AM_I_VALUE = 0x68  # also at address 0x69: the register holds the AD0-less address

GYRO_LSB_PER_DPS = 131.0  # GYRO_CONFIG = 0: +-250 deg/s
ACCEL_LSB_PER_G = 16384.0  # ACCEL_CONFIG = 0: +-2 g
STANDARD_GRAVITY_M_S2 = 9.80665
GYRO_OUTPUT_RATE_HZ = 1000.0  # with the low-pass filter on
WAKE_SETTLE_S = 0.1  # the gyro PLL needs some tens of ms after wake-up


@dataclass(frozen=True)
class RawImu:
    """One burst read in chip axes and raw counts."""

    accel: tuple[int, int, int]
    temperature: int
    gyro: tuple[int, int, int]


@dataclass(frozen=True)
class GyroCalibration:
    bias_counts: tuple[float, float, float]  # chip axes [LSB]
    yaw_bias_dps: float  # bias of the yaw rate, counter-clockwise positive [deg/s]
    yaw_std_dps: float  # spread of the up-axis rate while still [deg/s]
    gravity_up_g: float  # acceleration along the robot's up axis while still, about +1 when level [g]
    samples: int


class Mpu6050:
    """An MPU-6050 configured for +-250 deg/s and +-2 g, reporting in the robot frame.

    The robot frame is x forward, y left, z up; the mounting axes say which signed chip axis
    points along each. The gyro measures right-handed rotation about each chip axis, so with the
    chip's +z pointing up a positive z rate is a counter-clockwise yaw seen from above.
    """

    def __init__(
        self,
        bus: I2cBus,
        *,
        bus_number: int,
        address: int = 0x68,
        forward_axis: str = "+x",
        left_axis: str = "+y",
        up_axis: str = "+z",
        dlpf: int = 3,
        sample_rate_hz: float = 100.0,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self._bus = bus
        self.bus_number = bus_number
        self.address = address
        self.where = f"IMU on I2C bus {bus_number} at {address:#04x}"
        self._forward = _axis(forward_axis)
        self._left = _axis(left_axis)
        self._up = _axis(up_axis)
        self.up_axis = up_axis
        self.bias_counts: tuple[float, float, float] = (0.0, 0.0, 0.0)
        try:
            self.who_am_i = bus.read_byte_data(address, WHO_AM_I)
        except OSError as exc:
            raise HardwareError(
                f"no device answers: {self.where} ({exc.strerror or exc}); check wiring and `i2cdetect -y {bus_number}`"
            ) from None
        if self.who_am_i != WHO_AM_I_VALUE:
            raise HardwareError(
                f"{self.where}: WHO_AM_I reads {self.who_am_i:#04x}, expected {WHO_AM_I_VALUE:#04x} (not an MPU-6050)"
            )
        divider = min(255, max(0, round(GYRO_OUTPUT_RATE_HZ / sample_rate_hz) - 1))
        try:
            bus.write_byte_data(address, PWR_MGMT_1, 0x01)  # awake, clocked from the X gyro PLL
            sleep(WAKE_SETTLE_S)
            bus.write_byte_data(address, SMPLRT_DIV, divider)
            bus.write_byte_data(address, CONFIG, dlpf)
            bus.write_byte_data(address, GYRO_CONFIG, 0x00)
            bus.write_byte_data(address, ACCEL_CONFIG, 0x00)
        except OSError as exc:
            raise HardwareError(f"{self.where}: configuration failed ({exc.strerror or exc})") from None

    def read_raw(self) -> RawImu:
        data = self._bus.read_i2c_block_data(self.address, ACCEL_XOUT_H, 14)
        ax, ay, az, temperature, gx, gy, gz = struct.unpack(">7h", bytes(data))
        return RawImu(accel=(ax, ay, az), temperature=temperature, gyro=(gx, gy, gz))

    def to_sample(self, raw: RawImu, t_s: float) -> ImuSample:
        """Convert to robot-frame SI units, bias removed."""
        gyro = [raw.gyro[i] - self.bias_counts[i] for i in range(3)]
        yaw_dps = _component(gyro, self._up) / GYRO_LSB_PER_DPS
        accel_scale = STANDARD_GRAVITY_M_S2 / ACCEL_LSB_PER_G
        return ImuSample(
            t_s=t_s,
            gyro_z_rad_s=math.radians(yaw_dps),
            accel_x_m_s2=_component(raw.accel, self._forward) * accel_scale,
            accel_y_m_s2=_component(raw.accel, self._left) * accel_scale,
        )

    @staticmethod
    def temperature_c(raw: RawImu) -> float:
        return raw.temperature / 340.0 + 36.53

    def calibrate(
        self,
        samples: int,
        period_s: float,
        *,
        still_max_std_dps: float = 1.0,
        sleep: Callable[[float], None] = time.sleep,
    ) -> GyroCalibration:
        """Average the gyro while the robot stands still and use the mean as its bias from now on."""
        gyro_sum = [0.0, 0.0, 0.0]
        yaw: list[float] = []
        up_g = 0.0
        for _ in range(samples):
            raw = self.read_raw()
            for i in range(3):
                gyro_sum[i] += raw.gyro[i]
            yaw.append(_component(raw.gyro, self._up) / GYRO_LSB_PER_DPS)
            up_g += _component(raw.accel, self._up) / ACCEL_LSB_PER_G
            sleep(period_s)
        mean_yaw = sum(yaw) / samples
        std_dps = math.sqrt(sum((y - mean_yaw) ** 2 for y in yaw) / samples)
        calibration = GyroCalibration(
            bias_counts=(gyro_sum[0] / samples, gyro_sum[1] / samples, gyro_sum[2] / samples),
            yaw_bias_dps=mean_yaw,
            yaw_std_dps=std_dps,
            gravity_up_g=up_g / samples,
            samples=samples,
        )
        if std_dps > still_max_std_dps:
            raise HardwareError(
                f"{self.where}: the robot moved during gyro calibration "
                f"(yaw rate spread {std_dps:.2f} deg/s); keep it still"
            )
        if calibration.gravity_up_g < -0.5:
            flipped = ("-" if self.up_axis[0] == "+" else "+") + self.up_axis[1]
            raise HardwareError(
                f"{self.where}: gravity reads {calibration.gravity_up_g:+.2f} g along up_axis={self.up_axis!r}: "
                f"the board is upside down for this config (try up_axis = {flipped!r} and flip left_axis)"
            )
        self.bias_counts = calibration.bias_counts
        return calibration


class ImuSampler:
    """Samples the IMU at a fixed rate on a daemon thread and buffers timestamped samples.

    ``poll()`` takes one sample and is what the thread calls, so tests can drive it directly.
    """

    MAX_CONSECUTIVE_ERRORS = 50

    def __init__(
        self, imu: Mpu6050, rate_hz: float, *, clock: Callable[[], float] = time.monotonic, buffer_s: float = 10.0
    ) -> None:
        self.imu = imu
        self.period_s = 1.0 / rate_hz
        self._clock = clock
        self._lock = threading.Lock()
        self._samples: deque[ImuSample] = deque(maxlen=max(1, int(buffer_s * rate_hz)))
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._errors = 0
        self.failure: HardwareError | None = None
        self.dropped = 0  # samples lost because nobody drained the buffer

    def poll(self) -> ImuSample | None:
        t0 = self._clock()
        try:
            raw = self.imu.read_raw()
        except OSError as exc:
            self._errors += 1
            if self._errors >= self.MAX_CONSECUTIVE_ERRORS and self.failure is None:
                reason = exc.strerror or exc
                self.failure = HardwareError(f"{self.imu.where}: {self._errors} reads failed in a row ({reason})")
            return None
        self._errors = 0
        sample = self.imu.to_sample(raw, 0.5 * (t0 + self._clock()))  # mid-transfer time
        with self._lock:
            if len(self._samples) == self._samples.maxlen:
                self.dropped += 1
            self._samples.append(sample)
        return sample

    def drain(self) -> list[ImuSample]:
        """Every sample since the previous call, oldest first."""
        if self.failure is not None:
            raise self.failure
        with self._lock:
            samples = list(self._samples)
            self._samples.clear()
        return samples

    def start(self) -> ImuSampler:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="sonarslam-imu", daemon=True)
            self._thread.start()
        return self

    def _run(self) -> None:
        next_s = self._clock()
        while not self._stop.is_set():
            try:
                self.poll()
            except Exception:  # keep sampling; a bug here must not silently end the IMU stream
                log.exception("IMU sampling failed")
            next_s += self.period_s
            now = self._clock()
            if next_s < now - self.period_s:  # fell behind (bus stall): restart the schedule
                next_s = now
            self._stop.wait(max(0.0, next_s - now))

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)
        self._thread = None


def _axis(name: str) -> tuple[int, int]:
    """'-y' -> (chip index 1, sign -1)."""
    vector = axis_vector(name)
    index = next(i for i in range(3) if vector[i])
    return index, vector[index]


def _component(values: tuple[int, int, int] | list[float], axis: tuple[int, int]) -> float:
    index, sign = axis
    return float(sign * values[index])
