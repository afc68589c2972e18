"""The step engine: the paper's Algorithms 1 and 2 on the hardware seam.

Each ``step()`` chooses the next navigation move (Algorithm 1), executes it closed-loop on the
dead-reckoning estimate, sweeps the sonars, updates the map (Algorithm 2) and returns the new pose
estimate with the map cells whose exported state changed. No asyncio and no I/O happen here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from robot.config import RobotConfig
from robot.explore import Action, Explorer
from robot.grid import OCCUPIED, UNKNOWN, dilate8, lone_occupied
from robot.hardware import Hardware
from robot.headingfix import WallFixes, repairs_possible
from robot.localization import DeadReckoning, PoseEstimate
from robot.mapping import make_mapper
from robot.mapping.base import MapFrame, blocked_by_extent
from robot.mapping.geometry import place_beams
from robot.mapping.journal import JournaledMapper
from robot.motion import Pilot
from robot.sensorlog import SensorLogWriter
from robot.slam_config import SlamConfig
from robot.truth import reachable_cells, truth_states

_NO_CELLS = (np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64))  # no change to the exported map


@dataclass
class StepResult:
    step: int
    t_s: float  # clock time at the end of the step [s]
    pose: PoseEstimate  # estimated pose, map frame
    action: str  # "start", "explore", "backtrack", "revisit", "frontier", "probe", "inspect", "unpin", "done"
    target_xy: tuple[float, float] | None  # where the robot was heading [m]
    changed_rows: NDArray[np.int64]
    changed_cols: NDArray[np.int64]
    changed_states: NDArray[np.int8]
    sweep_ranges_m: NDArray[np.float64] | None
    frontier_cells: int
    done: bool = False
    terminated_by: str | None = None
    moved_ok: bool = True


@dataclass
class EngineStats:
    steps: int = 0
    moves: int = 0
    failed_moves: int = 0
    sweeps: int = 0
    last_change_t: float = 0.0
    terminated_by: str | None = None
    actions: dict[str, int] = field(default_factory=dict)


def classify(
    belief: NDArray[np.int8], start_cell: tuple[int, int], passages: NDArray[np.bool_] | None = None
) -> NDArray[np.int8]:
    """The exported map: the belief read the way the ground truth is defined (SPEC §2).

    White = believed-free cells reachable from the start; black = cells that are not believed free
    and touch that area (occupied, or unknown next to explored space, which is treated as blocked);
    grey = everything else. ``passages`` (cells the robot drove into against the map) connect the
    area even when the belief holds them occupied: echo arcs smeared across a narrow gap the robot
    drove through do not cut off what lies beyond it; they stay black themselves.
    """
    blocked = belief != 0
    passage = blocked if passages is None else blocked & ~passages
    reach = reachable_cells(passage, *start_cell) & ~blocked
    return truth_states(blocked, reach)


class SlamEngine:
    """Explores with the robot behind ``hw`` and builds the map. Knows nothing of any world."""

    def __init__(
        self,
        hw: Hardware,
        robot: RobotConfig,
        config: SlamConfig,
        frame: MapFrame,
        on_tick: Callable[[PoseEstimate], None] | None = None,
        recorder: SensorLogWriter | None = None,
    ) -> None:
        config.check_robot(robot)
        self.hw = hw
        self.robot = robot
        self.config = config
        self.frame = frame
        self.dead_reckoning = DeadReckoning(robot, frame.start, config.localization)
        self.mapper = JournaledMapper(
            lambda: make_mapper(config.mapper, frame, robot, config),
            lambda: self.dead_reckoning.distance_m,
            keep=repairs_possible(frame, config.box_fix),
        )
        self.fixes = WallFixes(frame, robot, config.box_fix, config.heading_fix, config.line_fix)
        self._user_tick = on_tick
        self._last_body_xy = (frame.start.x, frame.start.y)
        self.recorder = recorder
        self.pilot = Pilot(hw, robot, self.dead_reckoning, config.motion, on_tick=self._on_tick, recorder=recorder)
        block = config.nav_block(robot)
        self.explorer = Explorer(
            frame.grid,
            block,
            (0, 0),
            max_inspections=config.max_inspections,
            max_probes=config.max_probes,
            max_unpins=config.max_unpins,
        )
        self.explorer.start_cell = self.explorer.nav_cell_of(frame.start.x, frame.start.y)
        self.stats = EngineStats(last_change_t=hw.now())
        self._last_change_step = 0  # the step at which the belief last changed
        self._exported = frame.grid.empty()
        self._belief = frame.grid.empty()
        self._passable = np.zeros(frame.grid.shape, dtype=bool)
        self._free_fraction = np.zeros(frame.grid.shape)
        self._outside = blocked_by_extent(frame)
        self._started = False
        self._failed_heading: float | None = None  # heading of the last move that failed [rad]
        self.last_sweep: NDArray[np.float64] | None = None
        self.done = False

    # -- state ---------------------------------------------------------------------------------
    @property
    def pose(self) -> PoseEstimate:
        return self.dead_reckoning.estimate

    def map_states(self) -> NDArray[np.int8]:
        """The exported black / white / grey map as of the last step."""
        return self._exported.copy()

    def belief(self) -> NDArray[np.int8]:
        return self.mapper.states()

    # -- internals -----------------------------------------------------------------------------
    def _on_tick(self, est: PoseEstimate) -> None:
        # The body clears the floor it drives over; marking every few centimetres is enough.
        if math.hypot(est.x - self._last_body_xy[0], est.y - self._last_body_xy[1]) >= 0.03:
            self.mapper.mark_body(est.as_pose())
            self._last_body_xy = (est.x, est.y)
        if self._user_tick is not None:
            self._user_tick(est)

    def _sweep(self) -> None:
        sweep, est = self.pilot.sweep()
        if self.recorder is not None:
            self.recorder.sweep(sweep)
        pose = self.fixes.apply(self.dead_reckoning, est.as_pose(), sweep.ranges_m, self.mapper.evidence())
        self.mapper.repair(self.fixes.take_repairs())
        self.mapper.integrate(pose, sweep.ranges_m)
        self.mapper.mark_body(pose)
        beams = place_beams(pose, sweep.ranges_m, self.robot)
        self.explorer.note_view(
            pose.x,
            pose.y,
            [b.axis_rad for b in beams],
            [math.hypot(b.x - pose.x, b.y - pose.y) + b.range_m if b.echo else math.inf for b in beams],
        )
        self.last_sweep = sweep.ranges_m
        self.stats.sweeps += 1

    def _go_to(self, cell: tuple[int, int]) -> bool:
        x, y = self.explorer.nav_center(cell)
        est = self.pose
        if math.hypot(x - est.x, y - est.y) > 1e-3:
            heading = math.atan2(y - est.y, x - est.x)
            # Turns are in multiples of 45 degrees, as in the paper.
            heading = round(heading / (math.pi / 4)) * (math.pi / 4)
            turned = self.pilot.turn_to(heading)
            if not turned.ok:
                return False
            moved = self.pilot.drive_to(x, y)
            if not moved.ok:
                self._failed_heading = heading
                pose, unexplained = self.fixes.contact(
                    self.dead_reckoning, moved.pose.as_pose(), heading, self.mapper.evidence()
                )
                if unexplained:
                    self.mapper.mark_contact(pose, heading)
                if self.recorder is not None:
                    self.recorder.contact(self.hw.now(), heading)
                return False
        return True

    def _unpin(self) -> bool:
        """Step off sideways from the line of the last move that failed, by ``unpin_m``: first to its
        left, and if that stalls (the side the body touches), to its right. True if either went."""
        along = self._failed_heading if self._failed_heading is not None else self.pose.theta
        for side in (1.0, -1.0):
            # A quarter turn off a heading that is a multiple of 45 degrees is one too.
            heading = along + side * math.pi / 2
            if not self.pilot.turn_to(heading).ok:
                continue
            est = self.pose
            d = self.config.unpin_m
            if self.pilot.drive_to(est.x + d * math.cos(heading), est.y + d * math.sin(heading)).ok:
                return True
        return False

    def _recover(self, home: tuple[int, int]) -> None:
        """After a failed move, return to the centre of the cell the move started from."""
        x, y = self.explorer.nav_center(home)
        est = self.pose
        if math.hypot(x - est.x, y - est.y) > 0.01:
            heading = math.atan2(y - est.y, x - est.x)
            if self.pilot.turn_to(heading).ok:
                self.pilot.drive_to(x, y)

    def _refresh(self, step_action: str, target_xy: tuple[float, float] | None, ok: bool) -> StepResult:
        belief = self.mapper.states()
        exported = self._exported  # the export of an unchanged belief (most steps change nothing)
        if belief.tobytes() != self._belief.tobytes():  # np.array_equal for one shape and dtype, cheaper
            # The time limit runs from the last change of what the robot knows, not of the exported
            # map: in a large hall the area explored beyond a strip not yet seen free to the end is
            # grey in the export (not reachable from the start) while the robot maps it.
            self.stats.last_change_t = self.hw.now()
            self._last_change_step = self.stats.steps
            exported = classify(belief, self.frame.start_cell, self.explorer.passages())
        self._belief = belief
        self._free_fraction = self.mapper.free_fraction()
        self._passable = self._free_fraction >= self.explorer.min_free_fraction
        changed = np.nonzero(exported != self._exported) if exported is not self._exported else _NO_CELLS
        self._exported = exported
        frontier = int(self.explorer.frontier(self._belief, self._passable).sum())
        return StepResult(
            step=self.stats.steps,
            t_s=self.hw.now(),
            pose=self.pose,
            action=step_action,
            target_xy=target_xy,
            changed_rows=changed[0].astype(np.int64),
            changed_cols=changed[1].astype(np.int64),
            changed_states=exported[changed],
            sweep_ranges_m=self.last_sweep,
            frontier_cells=frontier,
            moved_ok=ok,
        )

    def _settled(self, steps: int) -> bool:
        """Whether runs end when mapped and the belief has not changed for ``steps`` steps: walking
        on through explored floor teaches the map nothing more."""
        return self.config.end_when_mapped and self.stats.steps - self._last_change_step >= steps

    def _mapped(self) -> bool:
        """Whether the map is finished: nothing left to resolve in reach, the belief settled, and no
        occupied cell alone in free floor (a stray echo, which the sweeps of the rest of the walk
        would clear, or a chair leg: then the walk goes on, until the map has not changed for
        ``give_up_steps``: what the sweeps have not cleared by then is a chair leg)."""
        if not self._settled(self.config.settle_steps):
            return False
        if self.explorer.frontier(self._belief, self._passable, self._doubtful()).any():
            return False
        if self._probe_left():
            return False
        return self._settled(self.config.give_up_steps) or not lone_occupied(self._belief).any()

    def _probe_cells(self) -> NDArray[np.bool_]:
        """Occupied cells inside the room box that only echoes say are occupied: cells the robot has
        bumped into are its explorer's ``bumped``."""
        return (self._belief == OCCUPIED) & ~self._outside

    def _probe_left(self) -> bool:
        """Whether the explorer would still drive into a cell that echoes alone close off."""
        est = self.pose
        current = self.explorer.nav_cell_of(est.x, est.y)
        if not (0 <= current[0] < self.explorer.nav_rows and 0 <= current[1] < self.explorer.nav_cols):
            return False
        trav = self.explorer.traversable_at(current, self._free_fraction)
        return self.explorer.probe(current, trav, self._probe_cells(), self._free_fraction) is not None

    def _doubtful(self) -> NDArray[np.bool_] | None:
        """Occupied cells (not the room's surveyed wall) that touch unknown space: worth a closer look."""
        if not self.config.inspect_walls:
            return None
        occupied = (self._belief == OCCUPIED) & ~self._outside
        return occupied & dilate8(self._belief == UNKNOWN)

    def _finalize_map(self) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int8]]:
        """Let the mapper settle every piece of evidence once more; returns the cells that changed."""
        self.mapper.finalize()
        self._belief = self.mapper.states()
        exported = classify(self._belief, self.frame.start_cell, self.explorer.passages())
        changed = np.nonzero(exported != self._exported) if exported is not self._exported else _NO_CELLS
        self._exported = exported
        return changed[0].astype(np.int64), changed[1].astype(np.int64), exported[changed]

    def _finish(self, result: StepResult, reason: str) -> StepResult:
        self.hw.stop()
        self.done = True
        self.stats.terminated_by = reason
        rows, cols, states = self._finalize_map()
        if rows.size:
            # Merge with the step's own changes, the final state of each cell winning.
            merged: dict[tuple[int, int], int] = {}
            for r, c, s in zip(result.changed_rows, result.changed_cols, result.changed_states, strict=True):
                merged[(int(r), int(c))] = int(s)
            for r, c, s in zip(rows, cols, states, strict=True):
                merged[(int(r), int(c))] = int(s)
            keys = list(merged)
            result.changed_rows = np.array([k[0] for k in keys], dtype=np.int64)
            result.changed_cols = np.array([k[1] for k in keys], dtype=np.int64)
            result.changed_states = np.array([merged[k] for k in keys], dtype=np.int8)
        result.done = True
        result.terminated_by = reason
        return result

    # -- Algorithm 1 --------------------------------------------------------------------------
    def step(self) -> StepResult:
        """One step: decide, move, sweep, map. Returns the pose and the changed cells."""
        if self.done:
            raise RuntimeError("the run has finished")
        self.stats.steps += 1
        if not self._started:
            self._started = True
            self.mapper.mark_body(self.frame.start)
            self._sweep()
            start_nav = self.explorer.start_cell
            ok = self._go_to(start_nav)
            self._sweep()
            return self._refresh("start", self.explorer.nav_center(start_nav), ok)

        est = self.pose
        current = self.explorer.nav_cell_of(est.x, est.y)
        action: Action = self.explorer.decide(
            current, est.theta, self._belief, self._passable, self._free_fraction, self._doubtful(),
            seek_frontier=self._settled(self.config.seek_frontier_steps),
            give_up_closed=self._settled(self.config.give_up_steps), probe_cells=self._probe_cells(),
        )  # fmt: skip
        self.stats.actions[action.reason] = self.stats.actions.get(action.reason, 0) + 1
        ok = True
        target_xy = None
        if action.kind == "move" and action.target is not None:
            target_xy = self.explorer.nav_center(action.target)
            self.stats.moves += 1
            ok = self._go_to(action.target)
            if not ok:
                self.stats.failed_moves += 1
                self.explorer.bumped[action.target] = True
                self._recover(current)
            self._sweep()
            result = self._refresh(action.reason, target_xy, ok)
        elif action.kind == "unpin":
            ok = self._unpin()
            self._sweep()
            result = self._refresh("unpin", None, ok)
        elif action.kind == "inspect" and action.heading_rad is not None:
            self.pilot.turn_to(action.heading_rad)
            self._sweep()
            result = self._refresh("inspect", None, True)
        else:
            result = self._refresh("done", None, True)
            return self._finish(result, action.reason or "complete")

        if self._mapped():
            return self._finish(result, "complete")
        now = self.hw.now()
        if now - self.stats.last_change_t > self.config.time_limit_s:
            return self._finish(result, "time_limit")
        if self.stats.steps >= self.config.max_steps or now >= self.config.max_sim_time_s:
            return self._finish(result, "safety_cap")
        return result

    def stop(self, reason: str = "stopped") -> StepResult:
        """End the run early; the map so far is kept. Returns the final cell changes."""
        self.hw.stop()
        self.done = True
        self.stats.terminated_by = reason
        rows, cols, states = self._finalize_map()
        return StepResult(
            step=self.stats.steps,
            t_s=self.hw.now(),
            pose=self.pose,
            action="stop",
            target_xy=None,
            changed_rows=rows,
            changed_cols=cols,
            changed_states=states,
            sweep_ranges_m=self.last_sweep,
            frontier_cells=0,
            done=True,
            terminated_by=reason,
        )
