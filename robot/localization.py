"""Dead reckoning: a linear Kalman filter fusing gyro and encoder yaw rates, plus encoder odometry.

State ``[theta, omega, bias]``: heading [rad], yaw rate [rad/s], gyro bias [rad/s]. Measurements are
the mean gyro rate over a tick (which sees ``omega + bias``) and the encoder yaw rate (which sees
``omega``). When the wheels have not turned, a zero-rate pseudo-measurement pins omega, which makes
the bias observable. When the gyro and the encoders disagree by more than the encoders' quantisation
explains (slip, bumps), the encoder variance is inflated: Borenstein & Feng's gyrodometry.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from robot.config import RobotConfig
from robot.hardware import EncoderCounts, ImuSample, gyro_rates
from robot.world import Pose


class LocalizationConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    gyro_noise_std_rad_s: float = Field(default=0.0015, gt=0.0)  # per IMU sample
    yaw_rate_jump_std_rad_s: float = Field(default=2.0, gt=0.0)  # how much omega may change between ticks
    bias_walk_std_rad_s2: float = Field(default=0.0005, gt=0.0)  # process noise on the bias
    initial_bias_std_rad_s: float = Field(default=0.05, gt=0.0)
    zero_rate_std_rad_s: float = Field(default=0.0005, gt=0.0)  # wheels still => omega ~ 0
    encoder_rate_std_floor_rad_s: float = Field(default=0.001, gt=0.0)  # least doubt in an encoder yaw rate
    slip_gate_sigma: float = Field(default=3.0, gt=0.0)  # disagreement that counts as slip [std-devs]
    slip_inflation: float = Field(default=100.0, ge=1.0)  # encoder variance factor under slip


class PoseEstimate(NamedTuple):
    """The estimate after a tick (immutable: a named tuple is also several times cheaper to create than
    a dataclass, and dead reckoning makes one every control tick)."""

    x: float  # [m], map frame
    y: float  # [m]
    theta: float  # [rad]
    theta_std: float  # [rad]
    bias: float  # estimated gyro bias [rad/s]

    def as_pose(self) -> Pose:
        return Pose(self.x, self.y, self.theta)


def _small_inverse(m: NDArray[np.float64]) -> NDArray[np.float64]:
    """The inverse of the filter's 1 x 1 or 2 x 2 innovation covariance in closed form: a quarter of
    the cost of ``np.linalg.inv``, which filterpy lets a filter replace (``KalmanFilter.inv``)."""
    if m.shape == (2, 2):
        (a, b), (c, d) = m.tolist()
        det = a * d - b * c
        return np.array([[d / det, -b / det], [-c / det, a / det]])
    if m.shape == (1, 1):
        return np.array([[1.0 / float(m[0, 0])]])
    return np.asarray(np.linalg.inv(m), dtype=np.float64)


def wrap_angle(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


class DeadReckoning:
    """Tracks the pose from successive encoder counts and IMU samples, starting at ``start``."""

    def __init__(self, robot: RobotConfig, start: Pose, config: LocalizationConfig | None = None) -> None:
        self.robot = robot
        # filterpy's package pulls in scipy.stats (about half a second): imported here rather than with
        # this module, so that the command line and the service can check their input before it.
        from filterpy.kalman import KalmanFilter

        self.config = cfg = config or LocalizationConfig()
        self._kf = KalmanFilter(dim_x=3, dim_z=2)
        kf = self._kf
        kf.inv = _small_inverse
        kf.x = np.array([start.theta, 0.0, 0.0])
        kf.P = np.diag([1e-8, 1e-4, cfg.initial_bias_std_rad_s**2])
        # z = [gyro rate, turn rate]: the gyro reads rate + bias; the turn rate comes from the encoders,
        # or is the zero-rate pseudo-measurement when the wheels are still. One H serves both, and is
        # passed explicitly: filterpy then skips reshaping z, with the same numbers.
        kf.H = np.array([[0.0, 1.0, 1.0], [0.0, 1.0, 0.0]])
        # Filled in place at every tick (dt and the measurement variances change; the layout does not).
        kf.F = np.eye(3)
        kf.Q = np.zeros((3, 3))
        # The two-measurement update's R is the filter's own, filled in place: passing it to
        # ``update`` would cost a scalar check on every tick.
        kf.R = self._R2 = np.zeros((2, 2))
        self._z2 = np.zeros(2)
        self._x = start.x
        self._y = start.y
        self._odo_x = start.x  # the same, without external position fixes
        self._odo_y = start.y
        self._last_counts: tuple[int, int] | None = None
        self._last_t: float | None = None
        # Encoder yaw-rate quantisation: each wheel's count is off by up to one count.
        self._enc_yaw_quantum = robot.metres_per_count / robot.wheel_base_m  # [rad]
        self.slip_events = 0
        self.distance_m = 0.0  # driven, by the encoders (turns on the spot add nothing)
        # The same numbers every tick, worked out once.
        self._metres_per_count = robot.metres_per_count
        self._yaw_jump_var = cfg.yaw_rate_jump_std_rad_s**2  # [(rad/s)^2]
        self._bias_walk_var = cfg.bias_walk_std_rad_s2**2  # [(rad/s)^2 per s]
        self._encoder_floor_var = cfg.encoder_rate_std_floor_rad_s**2
        self._gyro_var = cfg.gyro_noise_std_rad_s**2  # one sample's
        self._zero_rate_var = cfg.zero_rate_std_rad_s**2
        self._new_estimate()

    @property
    def estimate(self) -> PoseEstimate:
        return self._estimate

    def _new_estimate(self) -> PoseEstimate:
        """The estimate from the filter's state and the position; kept until either changes."""
        x = self._kf.x
        self._estimate = PoseEstimate(
            self._x, self._y, wrap_angle(float(x[0])), math.sqrt(max(self._kf.P[0, 0], 0.0)), float(x[2])
        )
        return self._estimate

    @property
    def odometry_xy(self) -> tuple[float, float]:
        """The position from odometry alone [m]: what it would be without ``shift_position``."""
        return self._odo_x, self._odo_y

    def shift_position(self, dx: float, dy: float) -> PoseEstimate:
        """Move the position estimate by an external fix [m]."""
        self._x += dx
        self._y += dy
        return self._new_estimate()

    def correct_heading(self, delta_rad: float, std_rad: float) -> PoseEstimate:
        """An external measurement of the heading error (true minus estimated) [rad], as a Kalman
        update: the filter weighs it against its own doubt and corrects the gyro bias with it."""
        kf = self._kf
        z = np.array([float(kf.x[0]) + delta_rad])
        kf.update(z, R=np.array([[std_rad**2]]), H=np.array([[1.0, 0.0, 0.0]]))
        return self._new_estimate()

    def reset_origin(self, counts: EncoderCounts) -> None:
        """Take the current counts as the reference (call once before the first update)."""
        self._last_counts = (counts.left, counts.right)
        self._last_t = counts.t_s

    def update(self, counts: EncoderCounts, imu: Sequence[ImuSample], wheels_commanded: bool = False) -> PoseEstimate:
        """Advance the estimate to ``counts.t_s`` with the IMU samples taken since the last update.

        ``wheels_commanded`` says whether the wheels were driven during the interval: at low speed a
        wheel can turn for a while without an encoder count, so unchanged counts alone do not mean
        the robot was still.
        """
        if self._last_counts is None or self._last_t is None:
            self.reset_origin(counts)
            return self.estimate
        dt = counts.t_s - self._last_t
        if dt <= 0:
            return self.estimate
        dl_counts = counts.left - self._last_counts[0]
        dr_counts = counts.right - self._last_counts[1]
        self._last_counts = (counts.left, counts.right)
        self._last_t = counts.t_s
        mpc = self._metres_per_count
        dl, dr = dl_counts * mpc, dr_counts * mpc
        cfg = self.config
        kf = self._kf

        theta_before = float(kf.x[0])
        # omega is the mean yaw rate over the tick; it may jump at the tick's start (a new wheel
        # command), and the heading integrates the new value over the whole tick.
        kf.F[0, 1] = dt
        qw = self._yaw_jump_var
        q = kf.Q
        q[0, 0], q[0, 1], q[1, 0], q[1, 1] = qw * dt * dt, qw * dt, qw * dt, qw
        q[2, 2] = self._bias_walk_var * dt
        kf.predict()

        enc_rate = (dr - dl) / self.robot.wheel_base_m / dt
        # Two uniform one-count errors, and never better than the floor. (Over a short turn the counts
        # lag the wheels and nudge the bias estimate; a 0.5 rad/s floor removed that but, measured over
        # whole runs, lost more than it gained: 3.9 cm against 2.3 cm of final position error.)
        enc_var = max((self._enc_yaw_quantum / dt) ** 2 / 3.0, self._encoder_floor_var)
        if imu:
            # np.mean's own arithmetic (one pairwise sum, then a division), without its overhead.
            gyro_rate = float(np.add.reduce(gyro_rates(imu))) / len(imu)
            gyro_var = self._gyro_var / len(imu)
            still = dl_counts == 0 and dr_counts == 0 and not wheels_commanded
            z, r = self._z2, self._R2
            if still:
                # Zero-rate pseudo-measurement and the gyro together: the gyro then reads the bias.
                z[0], z[1] = gyro_rate, 0.0
                r[0, 0], r[1, 1] = gyro_var, self._zero_rate_var
                kf.update(z, H=kf.H)
            else:
                innovation = gyro_rate - float(kf.x[2]) - enc_rate
                gate = cfg.slip_gate_sigma * math.sqrt(enc_var + gyro_var + float(kf.P[2, 2]))
                if abs(innovation) > gate:
                    enc_var *= cfg.slip_inflation
                    self.slip_events += 1
                z[0], z[1] = gyro_rate, enc_rate
                r[0, 0], r[1, 1] = gyro_var, enc_var
                kf.update(z, H=kf.H)
        else:
            kf.update(np.array([enc_rate]), R=np.array([[enc_var]]), H=kf.H[1:2])
        # Position: encoder distance along the mid-tick fused heading.
        ds = (dl + dr) / 2.0
        self.distance_m += abs(ds)
        theta_mid = 0.5 * (theta_before + float(kf.x[0]))
        step_x, step_y = ds * math.cos(theta_mid), ds * math.sin(theta_mid)
        self._x += step_x
        self._y += step_y
        self._odo_x += step_x
        self._odo_y += step_y
        return self._new_estimate()
