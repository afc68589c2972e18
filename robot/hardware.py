"""The hardware seam: everything the SLAM side may touch, implemented by the simulator and the Pi backend.

The SLAM code receives only what real hardware gives: sonar ranges, cumulative encoder counts,
IMU samples and a clock. Nothing here exposes a world or a true pose.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol, overload, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True)
class SonarSweep:
    """One reading from every sonar, in mounting order (index i = ``RobotConfig.sonars[i]``).

    A range at or above the sonar model's ``max_range_m`` means "no echo".
    """

    t_s: float  # clock time when the sweep finished [s]
    ranges_m: NDArray[np.float64]  # shape (n_sonars,) [m]


class EncoderCounts(NamedTuple):
    """Cumulative signed encoder counts since start; positive = wheel driving forward.

    Records read at every control tick are named tuples: immutable, and several times cheaper to
    create than a frozen dataclass (a simulated run creates hundreds of thousands of them)."""

    t_s: float  # [s]
    left: int
    right: int


class ImuSample(NamedTuple):
    """One IMU sample in the robot frame (x forward, y left, z up)."""

    t_s: float  # [s]
    gyro_z_rad_s: float  # yaw rate, counter-clockwise positive [rad/s]
    accel_x_m_s2: float = 0.0
    accel_y_m_s2: float = 0.0


class ImuBatch(Sequence[ImuSample]):
    """IMU samples kept as the arrays they were made in (the simulator makes a control tick's
    samples at once): a sequence of ``ImuSample`` whose gyro rates also come as one array, so that
    dead reckoning does not build them one sample at a time and take them apart again."""

    def __init__(self, t_s: NDArray[np.float64], gyro_z_rad_s: NDArray[np.float64]) -> None:
        self.t_s = t_s  # [s]
        self.gyro_z_rad_s = gyro_z_rad_s  # [rad/s]

    def __len__(self) -> int:
        return len(self.gyro_z_rad_s)

    @overload
    def __getitem__(self, i: int) -> ImuSample: ...

    @overload
    def __getitem__(self, i: slice) -> ImuBatch: ...

    def __getitem__(self, i: int | slice) -> ImuSample | ImuBatch:
        if isinstance(i, slice):
            return ImuBatch(self.t_s[i], self.gyro_z_rad_s[i])
        return ImuSample(float(self.t_s[i]), float(self.gyro_z_rad_s[i]))

    def __iter__(self) -> Iterator[ImuSample]:
        return map(ImuSample, self.t_s.tolist(), self.gyro_z_rad_s.tolist())


def gyro_rates(samples: Sequence[ImuSample]) -> NDArray[np.float64]:
    """The samples' yaw rates as an array [rad/s]."""
    if isinstance(samples, ImuBatch):
        return samples.gyro_z_rad_s
    return np.array([s.gyro_z_rad_s for s in samples], dtype=np.float64)


@runtime_checkable
class Hardware(Protocol):
    """A robot the SLAM loop can drive. The clock belongs to the hardware, so a simulator can run
    faster than real time while the Pi backend sleeps for real."""

    def now(self) -> float:
        """Current clock time [s]."""
        ...

    def sleep(self, duration_s: float) -> None:
        """Let ``duration_s`` of clock time pass (wheels keep their last command)."""
        ...

    def read_sonar_sweep(self) -> SonarSweep:
        """Fire every sonar once in the configured order; takes clock time."""
        ...

    def read_encoders(self) -> EncoderCounts: ...

    def read_imu(self) -> Sequence[ImuSample]:
        """Every IMU sample taken since the previous call, oldest first."""
        ...

    def set_wheel_speeds(self, left_m_s: float, right_m_s: float) -> None:
        """Command wheel rim speeds [m/s]; values beyond the robot's maximum are clipped."""
        ...

    def stop(self) -> None:
        """Stop both wheels now."""
        ...

    def close(self) -> None:
        """Stop the wheels and release the devices; safe to call twice."""
        ...
