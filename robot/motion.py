"""Closed-loop motion on the estimated pose: 45-degree turns in place and straight one-cell moves.

The same code drives the simulator and the Pi: it commands wheel speeds through the Hardware seam,
lets clock time pass, and stops on the dead-reckoning estimate (encoder distance for moves, fused
heading for turns).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

from pydantic import BaseModel, ConfigDict, Field

from robot.config import RobotConfig
from robot.hardware import EncoderCounts, Hardware, ImuSample, SonarSweep
from robot.localization import DeadReckoning, PoseEstimate, wrap_angle


class MotionConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    tick_s: float = Field(default=0.2, ge=0.01, le=0.5)  # control period [s]: 100 Hz at most
    drive_speed_m_s: float = Field(default=0.2, gt=0.0)  # cruise rim speed
    turn_speed_m_s: float = Field(default=0.08, gt=0.0)  # rim speed when turning in place
    min_speed_m_s: float = Field(default=0.05, gt=0.0)  # creep speed near the goal
    heading_tolerance_deg: float = Field(default=0.7, gt=0.0)
    position_tolerance_m: float = Field(default=0.004, gt=0.0)
    heading_gain: float = Field(default=2.0, ge=0.0)  # steering on the way [1/s]
    slow_down_m: float = Field(default=0.02, gt=0.0)  # start creeping this far from the goal
    slow_down_rad: float = Field(default=0.1, gt=0.0)
    stall_timeout_s: float = Field(default=1.5, gt=0.0)  # no encoder progress for this long = blocked
    settle_s: float = Field(default=0.05, ge=0.0)  # pause after stopping before a sweep


@dataclass
class MoveOutcome:
    ok: bool
    reason: str  # "arrived", "stalled", "timeout"
    pose: PoseEstimate


TickHook = Callable[[PoseEstimate], None]


class DeadReckoningRecorder(Protocol):
    def dead_reckoning(self, counts: EncoderCounts, imu: Sequence[ImuSample], driving: bool) -> None: ...

    def origin(self, counts: EncoderCounts) -> None: ...


class Pilot:
    """Executes turns and moves on hardware, keeping the dead-reckoning estimate current."""

    def __init__(
        self,
        hw: Hardware,
        robot: RobotConfig,
        dead_reckoning: DeadReckoning,
        config: MotionConfig | None = None,
        on_tick: TickHook | None = None,
        recorder: DeadReckoningRecorder | None = None,
    ) -> None:
        self.hw = hw
        self.robot = robot
        self.dr = dead_reckoning
        self.config = config or MotionConfig()
        self.on_tick = on_tick
        self.recorder = recorder
        self._driving = False
        origin = hw.read_encoders()
        self.dr.reset_origin(origin)
        if recorder is not None:
            recorder.origin(origin)
        hw.read_imu()  # discard anything taken before the origin

    @property
    def pose(self) -> PoseEstimate:
        return self.dr.estimate

    def _command(self, left_m_s: float, right_m_s: float) -> None:
        self.hw.set_wheel_speeds(left_m_s, right_m_s)
        self._driving = left_m_s != 0.0 or right_m_s != 0.0

    def _update(self, driving: bool) -> PoseEstimate:
        counts = self.hw.read_encoders()
        imu = self.hw.read_imu()
        if self.recorder is not None:
            self.recorder.dead_reckoning(counts, imu, driving)
        return self.dr.update(counts, imu, wheels_commanded=driving)

    def _tick(self, duration_s: float) -> PoseEstimate:
        driving = self._driving
        self.hw.sleep(duration_s)
        est = self._update(driving)
        if self.on_tick is not None:
            self.on_tick(est)
        return est

    def settle(self) -> PoseEstimate:
        """Stop and let the estimate catch up (zero-rate updates feed the bias estimate)."""
        self.hw.stop()
        # The first tick after stopping may still hold motion; the second is truly still.
        self._tick(max(self.config.settle_s, 1e-3))
        self._driving = False
        return self._tick(max(self.config.settle_s, 1e-3))

    def sweep(self) -> tuple[SonarSweep, PoseEstimate]:
        """A sonar sweep while standing still, with the pose it was taken from."""
        self.hw.stop()
        self._driving = False
        sweep = self.hw.read_sonar_sweep()
        est = self._update(False)
        if self.on_tick is not None:
            self.on_tick(est)
        return sweep, est

    def turn_to(self, heading_rad: float) -> MoveOutcome:
        cfg = self.config
        tol = math.radians(cfg.heading_tolerance_deg)
        est = self.pose
        deadline = self.hw.now() + 4.0 * math.pi * self.robot.wheel_base_m / (2 * cfg.min_speed_m_s) + 5.0
        while True:
            err = wrap_angle(heading_rad - est.theta)
            if abs(err) <= tol:
                self.hw.stop()
                return MoveOutcome(True, "arrived", self.settle())
            if self.hw.now() > deadline:
                self.hw.stop()
                return MoveOutcome(False, "timeout", self.settle())
            v = (
                cfg.turn_speed_m_s
                if abs(err) > cfg.slow_down_rad
                else max(cfg.min_speed_m_s, cfg.turn_speed_m_s * abs(err) / cfg.slow_down_rad)
            )
            rate = 2.0 * v / self.robot.wheel_base_m  # [rad/s]
            sign = 1.0 if err > 0 else -1.0
            self._command(-sign * v, sign * v)
            # Do not sleep past the goal: the last tick is shortened to the time left.
            est = self._tick(min(cfg.tick_s, max(abs(err) / rate, 0.005)))

    def drive_to(self, x: float, y: float) -> MoveOutcome:
        """Drive straight to (x, y) [m, map frame]; assumes the robot already faces it."""
        cfg = self.config
        est = self.pose
        start_dist = math.hypot(x - est.x, y - est.y)
        deadline = self.hw.now() + 3.0 * start_dist / cfg.min_speed_m_s + 2.0
        last_progress_t = self.hw.now()
        last_counts = self.hw.read_encoders()
        hx, hy = (x - est.x) / max(start_dist, 1e-9), (y - est.y) / max(start_dist, 1e-9)
        while True:
            along = (x - est.x) * hx + (y - est.y) * hy  # distance left along the path
            if along <= cfg.position_tolerance_m:
                self.hw.stop()
                return MoveOutcome(True, "arrived", self.settle())
            now = self.hw.now()
            if now > deadline:
                self.hw.stop()
                return MoveOutcome(False, "timeout", self.settle())
            counts = self.hw.read_encoders()
            if (counts.left, counts.right) != (last_counts.left, last_counts.right):
                last_progress_t = now
                last_counts = counts
            elif now - last_progress_t > cfg.stall_timeout_s:
                self.hw.stop()
                return MoveOutcome(False, "stalled", self.settle())
            v = (
                cfg.drive_speed_m_s
                if along > cfg.slow_down_m
                else max(cfg.min_speed_m_s, cfg.drive_speed_m_s * along / cfg.slow_down_m)
            )
            bearing = math.atan2(y - est.y, x - est.x) if along > 0.02 else est.theta
            steer = cfg.heading_gain * wrap_angle(bearing - est.theta) * self.robot.wheel_base_m / 2.0
            steer = max(-v / 2, min(v / 2, steer))
            self._command(v - steer, v + steer)
            est = self._tick(min(cfg.tick_s, max(along / v, 0.005)))
