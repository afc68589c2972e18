"""SimRobot: a differential-drive robot in a World, implementing the Hardware seam.

Physics runs in fixed ticks of one IMU period. A constant wheel command over a sleep is integrated
for all its ticks at once with numpy. The true pose is available to the test harness and the
scorer through ``true_pose``; the SLAM side only ever sees the Hardware methods.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numpy.typing import NDArray

from robot.config import RobotConfig, SimNoise
from robot.errors import WorldError
from robot.hardware import EncoderCounts, ImuBatch, ImuSample, SonarSweep
from robot.sim.sonar import Walls, cone_candidates, ray_blocked, simulate_ranges
from robot.world import Pose, World

PACE_SLICE_S = 0.05  # longest single wall-clock sleep while pacing a slow run


def check_start(world: World, robot: RobotConfig) -> None:
    """Refuse a world whose start leaves the robot's body overlapping a wall or an obstacle: such a
    robot could never move, and the run would end at once with nothing mapped."""
    clearance = float(Walls(world.segments).distance(np.array([world.start.x]), np.array([world.start.y]))[0])
    if clearance < robot.radius_m - 1e-9:
        raise WorldError(
            f"{world.name}: start ({world.start.x:g}, {world.start.y:g}) is {100 * clearance:.1f} cm from a wall "
            f"or obstacle, but the robot's body needs {100 * robot.radius_m:.1f} cm (its radius)"
        )


class SimRobot:
    """The simulated robot. ``speed`` paces the clock against wall time (None runs flat out)."""

    def __init__(
        self,
        world: World,
        robot: RobotConfig,
        noise: SimNoise,
        seed: int = 0,
        speed: float | None = None,
    ) -> None:
        check_start(world, robot)
        self.world = world
        self.robot = robot
        self.noise = noise
        self.speed = speed
        self._rng = np.random.default_rng(seed)
        self._segments = world.segments
        self._walls = Walls(world.segments)
        self._clear_here: float | None = None  # clearance of the body's centre [m], or a lower bound
        self._dt = 1.0 / robot.imu.rate_hz  # physics tick = IMU period [s]
        self._t = 0.0  # sim clock [s]
        self._x, self._y, self._theta = world.start.x, world.start.y, world.start.theta
        self._cmd = (0.0, 0.0)  # commanded rim speeds [m/s]
        self._wheel_angle_l = 0.0  # [rad], cumulative
        self._wheel_angle_r = 0.0
        self._radius_true = (
            robot.wheel_radius_m * (1.0 + noise.wheel_radius_error_left),
            robot.wheel_radius_m * (1.0 + noise.wheel_radius_error_right),
        )
        self._gyro_bias = noise.gyro_bias_rad_s
        self._imu_t: list[NDArray[np.float64]] = []
        self._imu_w: list[NDArray[np.float64]] = []
        self._closed = False
        self.collisions = 0  # ticks in which the body hit something
        self.odometer_m = 0.0  # true distance travelled [m]
        self._wall_anchor: tuple[float, float] | None = None
        mounts = robot.sonars
        self._mount_xy = np.array([[m.offset_x_m, m.offset_y_m] for m in mounts])
        self._mount_bearing = np.radians([m.bearing_deg for m in mounts])
        self._half_beam = math.radians(robot.sonar.beam_width_deg) / 2.0

    # -- simulator-only views (never handed to the SLAM side) --------------------------------
    @property
    def true_pose(self) -> Pose:
        return Pose(self._x, self._y, self._theta)

    # -- Hardware seam ----------------------------------------------------------------------
    def now(self) -> float:
        return self._t

    def set_wheel_speeds(self, left_m_s: float, right_m_s: float) -> None:
        vmax = self.robot.max_wheel_speed_m_s
        self._cmd = (min(max(float(left_m_s), -vmax), vmax), min(max(float(right_m_s), -vmax), vmax))

    def stop(self) -> None:
        self._cmd = (0.0, 0.0)

    def close(self) -> None:
        self.stop()
        self._closed = True

    def read_encoders(self) -> EncoderCounts:
        per_rev = self.robot.encoder_counts_per_rev
        return EncoderCounts(
            self._t,
            math.floor(self._wheel_angle_l / (2.0 * math.pi) * per_rev),
            math.floor(self._wheel_angle_r / (2.0 * math.pi) * per_rev),
        )

    def read_imu(self) -> ImuBatch | list[ImuSample]:
        if not self._imu_t:
            return []
        if len(self._imu_t) == 1:
            ts, ws = self._imu_t[0], self._imu_w[0]
        else:
            ts, ws = np.concatenate(self._imu_t), np.concatenate(self._imu_w)
        self._imu_t.clear()
        self._imu_w.clear()
        return ImuBatch(ts, ws)

    def read_sonar_sweep(self) -> SonarSweep:
        n = len(self.robot.sonars)
        ranges = np.empty(n)
        if self._cmd == (0.0, 0.0):
            # Standing still: every ping sees the same pose, so cast them all at once.
            ranges[:] = self._ping(np.arange(n))
            self.sleep(self.robot.sonar.ping_interval_s * n)
        else:
            for i in self.robot.sonar.firing_order:
                self.sleep(self.robot.sonar.ping_interval_s)
                ranges[i] = self._ping(np.array([i]))[0]
        return SonarSweep(self._t, ranges)

    def sleep(self, duration_s: float) -> None:
        if duration_s <= 0:
            return
        self._pace(duration_s)
        ticks = max(1, int(round(duration_s / self._dt)))
        self._advance(ticks, duration_s / ticks)

    # -- internals ------------------------------------------------------------------------------
    def _pace(self, duration_s: float) -> None:
        """Wait until ``duration_s`` more of sim time is due in wall time, in short slices: a speed
        change from another thread (a stop sets None) takes effect within one slice, not after a
        sweep that lasts half a minute at a slow speed. A change mid-wait paces this wait afresh."""
        end = self._t + duration_s
        while True:
            speed = self.speed
            if not speed:
                self._wall_anchor = None
                return
            now_wall = time.monotonic()
            anchor = self._wall_anchor
            if anchor is None:
                anchor = self._wall_anchor = (now_wall, self._t)
            wall0, sim0 = anchor
            due = wall0 + (end - sim0) / speed
            if due <= now_wall:
                return
            time.sleep(min(due - now_wall, PACE_SLICE_S))

    def set_speed(self, speed: float | None) -> None:
        """Change the real-time factor live (None = as fast as possible)."""
        self.speed = speed
        self._wall_anchor = None

    def _ping(self, idx: NDArray[np.int64]) -> NDArray[np.float64]:
        c, s = math.cos(self._theta), math.sin(self._theta)
        mx, my = self._mount_xy[idx].T
        origins = np.empty((idx.size, 2))
        origins[:, 0] = self._x + c * mx - s * my
        origins[:, 1] = self._y + s * mx + c * my
        bearings = self._theta + self._mount_bearing[idx]
        dist, inc, points = cone_candidates(self._walls, origins, bearings, self._half_beam)
        segs = self._segments

        def occluded(i: int, j: int) -> bool:
            ox, oy = origins[i]
            return ray_blocked(segs, ox, oy, ox + points[i, j, 0], oy + points[i, j, 1], j)

        return simulate_ranges(dist, inc, self.robot.sonar, self.noise, self._rng, occluded)

    def _advance(self, ticks: int, dt: float) -> None:
        noise = self.noise
        wl, wr = self._cmd[0] / self.robot.wheel_radius_m, self._cmd[1] / self.robot.wheel_radius_m  # [rad/s]
        # One batch of random numbers per call: slip for both wheels, gyro bias walk, gyro noise.
        draws = self._rng.standard_normal((ticks, 4))
        rate: NDArray[np.float64] | float = 0.0
        if wl != 0.0 or wr != 0.0:
            rl, rr = self._radius_true
            slip = noise.wheel_slip_std
            gl = wl * dt * rl * (1.0 + slip * draws[:, 0])  # ground travel of each wheel per tick [m]
            gr = wr * dt * rr * (1.0 + slip * draws[:, 1])
            ds = 0.5 * (gl + gr)
            dth = (gr - gl) / self.robot.wheel_base_m
            # Running sums from the current pose, tick after tick (accumulate adds in order, as a loop
            # would), each in a buffer that starts with the current value.
            run = np.empty((3, ticks + 1))
            run[:, 0] = self._theta, self._x, self._y
            run[0, 1:] = dth
            ths = np.add.accumulate(run[0])
            mid = ths[:-1] + 0.5 * dth
            np.multiply(ds, np.cos(mid), out=run[1, 1:])
            np.multiply(ds, np.sin(mid), out=run[2, 1:])
            xs = np.add.accumulate(run[1])[1:]
            ys = np.add.accumulate(run[2])[1:]
            ths = ths[1:]
            rate = wheel_rate = dth / dt
            path = np.add.accumulate(np.abs(ds))
            ok = ticks
            radius, path_m = self.robot.radius_m, float(path[-1])
            known = self._clear_here
            if path_m > 0.0 and known is not None and known - path_m >= radius + path_m + 1e-6:
                # The end point is within the path length of the start, whose clearance is known: it is
                # clear by more than the path length too (with a micrometre to spare for rounding).
                self._clear_here = known - path_m  # a lower bound, which is all the next check needs
            elif path_m > 0.0:
                # Every tick lies within the path length of the end point, so a clear end point with
                # that much to spare rules out a collision without checking each tick.
                end_clear = self._walls.distance(xs[-1:], ys[-1:])[0]
                self._clear_here = float(end_clear)
                if end_clear < radius + path[-1]:
                    clearance = self._walls.distance(xs, ys)
                    hit = np.flatnonzero(clearance < radius)
                    if hit.size:
                        self._clear_here = None
                        ok = int(hit[0])  # the body stops at the last free tick ...
                        self.collisions += ticks - ok
                        if wl + wr == 0.0:
                            # ... but a round body turning on the spot against a wall keeps turning
                            # (its wheels scrub): only its centre, which unequal wheels or slip would
                            # nudge into the wall, stays put.
                            xs[ok:] = xs[ok - 1] if ok > 0 else self._x
                            ys[ok:] = ys[ok - 1] if ok > 0 else self._y
                            path[ok:] = path[ok - 1] if ok > 0 else 0.0
                            ok = ticks
                        else:
                            wheel_rate[ok:] = 0.0  # ... and the wheels stall
            if ok > 0:
                self._x, self._y = float(xs[ok - 1]), float(ys[ok - 1])
                th = float(ths[ok - 1])
                self._theta = math.atan2(math.sin(th), math.cos(th))
                self._wheel_angle_l += wl * dt * ok
                self._wheel_angle_r += wr * dt * ok
                self.odometer_m += float(path[ok - 1])
        # Gyro: true yaw rate + slowly wandering bias + white noise, one sample per tick.
        bias = self._gyro_bias + np.add.accumulate(noise.gyro_bias_walk_rad_s2 * math.sqrt(dt) * draws[:, 2])
        self._gyro_bias = float(bias[-1])
        self._imu_t.append(self._t + dt * np.arange(1, ticks + 1, dtype=np.float64))
        self._imu_w.append(rate + bias + noise.gyro_noise_std_rad_s * draws[:, 3])
        self._t += dt * ticks
