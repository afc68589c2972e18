"""The SLAM core: dead reckoning, the mappers, the explorer and the step engine."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from robot.boxfix import box_offsets
from robot.config import RobotConfig, SimNoise
from robot.engine import SlamEngine, classify
from robot.errors import ConfigError
from robot.explore import CLOCKWISE, Explorer, direction_index
from robot.grid import FREE, OCCUPIED, UNKNOWN, GridSpec, lone_occupied
from robot.hardware import EncoderCounts, ImuBatch, ImuSample
from robot.localization import DeadReckoning
from robot.mapping import make_mapper
from robot.mapping.base import MapFrame
from robot.mapping.geometry import place_beams
from robot.mapping.logodds import LogOddsMapper, LogOddsParams
from robot.metrics import score
from robot.runner import RunResult, frame_for_world, simulate
from robot.settings import load_run_config
from robot.slam_config import SlamConfig
from robot.truth import truth_grid
from robot.world import Pose, load_world, world_from_dict

ROBOT = RobotConfig()


def small_world(obstacles=()):
    return world_from_dict(
        {
            "name": "small",
            "boundary": [[0.0, 0.0], [2.0, 0.0], [2.0, 1.6], [0.0, 1.6]],
            "start": {"x": 0.3, "y": 0.3, "theta_deg": 90.0},
            "obstacles": list(obstacles),
        },
        "small.toml",
    )


# -- dead reckoning ----------------------------------------------------------------------------
def test_standing_still_teaches_the_filter_the_gyro_bias() -> None:
    dr = DeadReckoning(ROBOT, Pose(0.0, 0.0, 0.0))
    dr.reset_origin(EncoderCounts(0.0, 0, 0))
    rng = np.random.default_rng(0)
    t = 0.0
    for _ in range(100):  # 10 s still, a biased noisy gyro
        samples = [ImuSample(t + 0.01 * (i + 1), 0.02 + 0.0015 * rng.standard_normal()) for i in range(10)]
        t += 0.1
        est = dr.update(EncoderCounts(t, 0, 0), samples, wheels_commanded=False)
    assert est.bias == pytest.approx(0.02, abs=0.002)
    assert abs(est.theta) < math.radians(0.5)


def test_heading_follows_the_gyro_through_a_turn() -> None:
    dr = DeadReckoning(ROBOT, Pose(0.0, 0.0, 0.0))
    dr.reset_origin(EncoderCounts(0.0, 0, 0))
    rate = 1.0  # rad/s, counter-clockwise
    t = 0.0
    counts = 0.0
    for _ in range(10):  # 1 s of turning in place: the wheels turn in opposite directions
        samples = [ImuSample(t + 0.01 * (i + 1), rate) for i in range(10)]
        t += 0.1
        counts += rate * 0.1 * ROBOT.wheel_base_m / 2 / ROBOT.metres_per_count
        est = dr.update(EncoderCounts(t, -int(counts), int(counts)), samples, wheels_commanded=True)
    # Truncated counts lag the wheels during a short turn and pull the estimate a little towards them.
    assert est.theta == pytest.approx(1.0, abs=0.02)
    assert math.hypot(est.x, est.y) < 0.01


def test_encoder_slip_against_the_gyro_is_flagged_and_down_weighted() -> None:
    dr = DeadReckoning(ROBOT, Pose(0.0, 0.0, 0.0))
    dr.reset_origin(EncoderCounts(0.0, 0, 0))
    t = 0.0
    left = right = 0
    for _ in range(10):  # the right wheel spins 3x faster (slipping); the gyro says straight
        samples = [ImuSample(t + 0.01 * (i + 1), 0.0) for i in range(10)]
        t += 0.1
        left += 5
        right += 15
        est = dr.update(EncoderCounts(t, left, right), samples, wheels_commanded=True)
    assert dr.slip_events >= 5
    assert abs(est.theta) < math.radians(2.0)


def test_driving_straight_integrates_encoder_distance_along_the_heading() -> None:
    dr = DeadReckoning(ROBOT, Pose(1.0, 2.0, math.pi / 2))
    dr.reset_origin(EncoderCounts(0.0, 0, 0))
    n = 0
    for k in range(1, 11):
        n += 5
        dr.update(EncoderCounts(0.1 * k, n, n), [ImuSample(0.1 * k, 0.0)], wheels_commanded=True)
    est = dr.estimate
    assert est.x == pytest.approx(1.0, abs=1e-6)
    assert est.y == pytest.approx(2.0 + 50 * ROBOT.metres_per_count, abs=1e-6)


def test_samples_in_arrays_give_the_same_estimate_as_samples_one_by_one() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(1, 201) * 0.01
    gyro = 0.3 + 0.002 * rng.standard_normal(200)
    batch = ImuBatch(t, gyro)
    assert list(batch) == [ImuSample(float(a), float(b)) for a, b in zip(t, gyro, strict=True)]
    assert batch[3] == ImuSample(float(t[3]), float(gyro[3])) and len(batch[10:30]) == 20
    one_by_one, in_arrays = (DeadReckoning(ROBOT, Pose(0.0, 0.0, 0.0)) for _ in range(2))
    for dr in (one_by_one, in_arrays):
        dr.reset_origin(EncoderCounts(0.0, 0, 0))
    for k in range(10):
        tick = slice(20 * k, 20 * (k + 1))
        counts = EncoderCounts(float(t[tick][-1]), -3 * (k + 1), 3 * (k + 1))
        a = one_by_one.update(counts, list(batch[tick]), wheels_commanded=True)
        b = in_arrays.update(counts, batch[tick], wheels_commanded=True)
        assert a == b  # bit for bit


def test_the_filters_closed_form_inverse_gives_numpys_estimates() -> None:
    """The filter inverts its innovation covariance in closed form; with numpy's general inverse
    the estimates agree to rounding, through turns, slip, standing still and a heading fix."""
    fast, reference = (DeadReckoning(ROBOT, Pose(0.0, 0.0, 0.0)) for _ in range(2))
    reference._kf.inv = np.linalg.inv
    rng = np.random.default_rng(4)
    left = right = 0
    for dr in (fast, reference):
        dr.reset_origin(EncoderCounts(0.0, 0, 0))
    for k in range(1, 121):
        t = 0.1 * k
        phase = (k // 20) % 3  # turn, slip, stand still
        if phase == 0:
            left, right = left - 3, right + 3
        elif phase == 1:
            left, right = left + 4, right + 11
        rate = 0.6 if phase == 0 else 0.0
        samples = [ImuSample(t - 0.1 + 0.01 * (i + 1), 0.01 + rate + 0.002 * rng.standard_normal()) for i in range(10)]
        a = fast.update(EncoderCounts(t, left, right), samples, wheels_commanded=phase != 2)
        b = reference.update(EncoderCounts(t, left, right), samples, wheels_commanded=phase != 2)
        assert a == pytest.approx(b, rel=1e-9, abs=1e-12)
        if k == 60:
            a, b = (dr.correct_heading(0.05, 0.01) for dr in (fast, reference))
            assert a == pytest.approx(b, rel=1e-9, abs=1e-12)
    assert fast.slip_events == reference.slip_events > 0


# -- mappers -----------------------------------------------------------------------------------
@pytest.mark.parametrize("mapper_name", ["logodds", "paper"])
def test_a_wall_seen_head_on_is_occupied_and_the_space_before_it_free(mapper_name: str) -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)  # 2 x 2 m, no known extent
    frame = MapFrame(grid=grid, start=Pose(0.3, 1.0, 0.0), extent=None)
    mapper = make_mapper(mapper_name, frame, ROBOT, SlamConfig(mapper=mapper_name))
    # A wall at x = 1.5 seen from several vantage points along y, the front sonar pointing at it.
    for y in np.arange(0.5, 1.6, 0.1):
        pose = Pose(0.5, float(y), 0.0)
        ranges = np.full(8, ROBOT.sonar.max_range_m)
        ranges[0] = 1.5 - 0.5 - ROBOT.sonars[0].offset_x_m
        for _ in range(3):
            mapper.integrate(pose, ranges)
    states = mapper.states()
    row = grid.world_to_index(0.5, 1.0)[0]
    wall_col = int(grid.world_to_index(1.55, 1.0)[1])
    assert states[row, wall_col] == OCCUPIED
    assert all(states[row, c] == FREE for c in range(int(grid.world_to_index(0.9, 1.0)[1]), wall_col - 1))


def test_a_no_echo_reading_clears_nothing() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(0.3, 1.0, 0.0), extent=None)
    mapper = make_mapper("logodds", frame, ROBOT, SlamConfig())
    for _ in range(10):
        mapper.integrate(Pose(0.3, 1.0, 0.0), np.full(8, ROBOT.sonar.max_range_m))
    assert np.all(mapper.states() == UNKNOWN)


def test_a_no_echo_reading_clears_its_first_metre_only_where_no_box_wall_is_in_range() -> None:
    """In a hall whose walls all lie beyond the sonar's range, nothing can have turned a ping away
    but furniture: a sweep that hears nothing clears the floor around the robot. Within range of a
    box wall the same sweep may be a row of specular misses, and clears nothing."""
    grid = GridSpec(0.0, 0.0, 0.2, 60, 60)  # 12 x 12 m
    silent = np.full(8, ROBOT.sonar.max_range_m)
    pose = Pose(6.1, 6.1, 0.0)
    r, c = (int(v) for v in grid.world_to_index(6.1, 6.1))

    def swept(extent: tuple[float, float, float, float] | None) -> NDArray[np.int8]:
        mapper = make_mapper("logodds", MapFrame(grid, pose, extent=extent), ROBOT, SlamConfig())
        for _ in range(3):
            mapper.integrate(pose, silent)
        return mapper.states()

    hall = swept((0.0, 0.0, 12.0, 12.0))
    ahead = [hall[r, c + k] for k in (3, 4)]  # 0.5-0.9 m along the front sonar's axis
    behind = [hall[r, c - k] for k in (3, 4)]
    assert ahead == behind == [FREE] * 2
    assert hall[r, c + 7] == hall[r, c - 7] == UNKNOWN  # 1.3-1.5 m out: past the first metre
    assert not np.any(hall == OCCUPIED)

    # The same sweeps 2.9 m from a box wall: the beams that face it clear nothing.
    near = swept((0.0, 0.0, 9.0, 12.0))
    assert [near[r, c + k] for k in (3, 4)] == [UNKNOWN] * 2  # towards the wall at x = 9
    assert [near[r, c - k] for k in (3, 4)] == [FREE] * 2  # 6 m from the wall at x = 0

    # And in a room of unknown size no wall is known to be out of range.
    assert np.all(swept(None) == UNKNOWN)


def test_a_robot_started_in_a_hall_beyond_sonar_range_of_every_wall_maps_the_floor_around_it() -> None:
    """Started in the middle of a 12 x 12 m hall, the robot hears nothing. It must still find free
    floor, drive out and map, rather than end at once with every cell unknown."""
    world = world_from_dict(
        {
            "name": "bighall",
            "boundary": [[0.0, 0.0], [12.0, 0.0], [12.0, 12.0], [0.0, 12.0]],
            "start": {"x": 6.0, "y": 6.0, "theta_deg": 0.0},
        },
        "bighall.toml",
    )
    cfg = load_run_config(None, {"max_steps": 60})
    result = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    assert result.steps == 60  # still exploring, not ended with nothing seen
    assert result.terminated_by == "safety_cap"
    r, c = (int(v) for v in result.grid.world_to_index(6.0, 6.0))
    assert np.count_nonzero(result.states == FREE) >= 100  # 4 m2 of floor
    assert result.states[r, c] == FREE
    assert np.all(result.truth[result.states == FREE] == FREE)  # and every cell it calls free is


def _front_echo_to(x_wall: float, pose: Pose) -> np.ndarray:
    """A sweep in which only the front sonar hears an echo, off a surface at ``x_wall``."""
    ranges = np.full(8, ROBOT.sonar.max_range_m)
    ranges[0] = x_wall - pose.x - ROBOT.sonars[0].offset_x_m
    return ranges


def test_a_beam_that_runs_on_past_a_wrong_echo_clears_it() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 15, 15)
    frame = MapFrame(grid=grid, start=Pose(0.5, 1.5, 0.0), extent=(0.0, 0.0, 3.0, 3.0))
    pose = Pose(0.5, 1.5, 0.0)
    row, ghost_col = (int(i) for i in grid.world_to_index(1.35, 1.5))

    def final_row(short_echoes: int, recheck_within: float = 0.25) -> np.ndarray:
        params = LogOddsParams(recheck_within=recheck_within)
        mapper = make_mapper("logodds", frame, ROBOT, SlamConfig(logodds=params))
        for x_wall in [1.3] * short_echoes + [2.2] * 12:  # short echoes, then the real wall farther on
            mapper.integrate(pose, _front_echo_to(x_wall, pose))
        mapper.finalize()
        return mapper.states()[row]

    # Two stray short echoes: the beams that later run on past them clear them.
    assert final_row(2)[ghost_col] == FREE
    assert all(final_row(2)[c] == FREE for c in range(ghost_col, int(grid.world_to_index(2.0, 1.5)[1])))
    # Without the re-check the ghost hides itself and everything behind it for good.
    assert final_row(2, recheck_within=0.0)[ghost_col] == OCCUPIED
    assert final_row(2, recheck_within=0.0)[ghost_col + 1] == UNKNOWN
    # A surface that echoed many times stays: later misses are more likely glancing than empty space.
    assert final_row(8)[ghost_col] == OCCUPIED


def test_cones_that_ran_on_through_a_surface_found_later_clear_nothing_behind_it_at_the_end() -> None:
    """A sonar whose echo off a surface is lost (at a glancing angle) may hear a farther one instead,
    as multipath does: its cone clears the floor inside the obstacle before any echo has shown its
    face, and the evidence stays. At the end every sweep's cones are cleared again, hidden behind
    what the whole run shows occupied (room2 at 0.1 m: the inside of a desk set at 30 degrees went
    white)."""
    grid = GridSpec(0.0, 0.0, 0.2, 15, 15)
    frame = MapFrame(grid=grid, start=Pose(0.5, 1.5, 0.0), extent=(0.0, 0.0, 3.0, 3.0))
    face_col = int(grid.world_to_index(1.7, 1.5)[1])

    def final_rows(final_occlusion: bool) -> np.ndarray:
        params = LogOddsParams(final_occlusion=final_occlusion)
        mapper = make_mapper("logodds", frame, ROBOT, SlamConfig(logodds=params))
        start = Pose(0.5, 1.5, 0.0)
        for _ in range(3):  # the long readings, through the block whose face is at x = 1.6
            mapper.integrate(start, _front_echo_to(2.8, start))
        for y in np.arange(0.8, 2.25, 0.1):  # then the face, from along it
            pose = Pose(0.5, float(y), 0.0)
            for _ in range(12):
                mapper.integrate(pose, _front_echo_to(1.6, pose))
        mapper.finalize()
        rows = [int(grid.world_to_index(1.5, y)[0]) for y in (1.3, 1.5, 1.7)]
        return mapper.states()[rows]

    kept, cleared = final_rows(False), final_rows(True)
    assert np.all(kept[:, face_col] == OCCUPIED) and np.all(cleared[:, face_col] == OCCUPIED)
    assert np.all(kept[:, face_col + 1] == FREE)  # behind the face: cleared by the long readings
    assert np.all(cleared[:, face_col + 1 :] == UNKNOWN)
    assert np.array_equal(kept[:, : face_col + 1], cleared[:, : face_col + 1])  # the room side is the same


def test_the_final_pass_gives_the_same_map_from_kept_cones_as_from_cones_worked_out_again() -> None:
    """The final pass reuses the cones each sweep's integration worked out while they fit in
    ``final_cache_mb``; a budget that holds none, or only some, makes the same map."""
    cfg = load_run_config(None, {})
    world = load_world("room2")

    def final_states(cache_mb: float) -> NDArray[np.int8]:
        params = cfg.slam.logodds.model_copy(update={"final_cache_mb": cache_mb})
        return simulate(world, cfg.robot, cfg.noise, cfg.slam.model_copy(update={"logodds": params}), seed=1).states

    kept = final_states(64.0)
    assert np.array_equal(kept, final_states(0.0))
    assert np.array_equal(kept, final_states(2.0))  # some sweeps kept, the rest worked out again


def test_the_final_pass_keeps_the_strip_just_in_front_of_a_solid_cell_a_beam_ran_on_past() -> None:
    """A beam that meets a face at a slant may hear nothing from it (a specular miss) and run on
    past it, clearing the strip in front of the solid cells: where the face cuts a few centimetres
    into the next map cell. When the run ends, cells less than ``final_front_cells``
    evidence cells in front of a solid one along such a beam stay as they were; the cell a whole
    evidence cell in front, as in front of a face on a cell boundary seen head-on, is cleared."""
    grid = GridSpec(0.0, 0.0, 0.2, 15, 15)
    frame = MapFrame(grid=grid, start=Pose(0.5, 1.0, 0.0), extent=(0.0, 0.0, 3.0, 3.0))

    def beside_solid(theta_deg: float, front_cells: float) -> tuple[float, float]:
        """Belief in the solid evidence cell 1 m out on the front beam's axis, and in the one 5 cm
        nearer along x, after readings that ran on past it to 2.5 m."""
        params = LogOddsParams(final_front_cells=front_cells)
        mapper = make_mapper("logodds", frame, ROBOT, SlamConfig(logodds=params))
        assert isinstance(mapper, LogOddsMapper)
        pose = Pose(0.5, 1.0, math.radians(theta_deg))
        ranges = np.full(8, ROBOT.sonar.max_range_m)
        ranges[0] = 2.5
        front = place_beams(pose, ranges, ROBOT)[0]
        solid_xy = front.x + math.cos(front.axis_rad), front.y + math.sin(front.axis_rad)
        row, col = (int(v) for v in mapper.fine.world_to_index(*solid_xy))
        mapper.contact_evidence[row, col] = 5.0
        mapper._changed()
        for _ in range(3):
            mapper.integrate(pose, ranges)
        mapper.finalize()
        return float(mapper.logodds[row, col]), float(mapper.logodds[row, col - 1])

    p = LogOddsParams()
    # At 30 degrees the cell 5 cm nearer along x is 4.3 cm nearer along the beam: kept ...
    solid, near = beside_solid(30.0, p.final_front_cells)
    assert solid >= p.occ_threshold and near > p.free_threshold
    # ... but cleared without the margin, as it is while exploring.
    assert beside_solid(30.0, 0.0)[1] <= p.free_threshold
    # Head-on, the cell in front of the solid one is a whole evidence cell nearer: cleared.
    assert beside_solid(0.0, p.final_front_cells)[1] <= p.free_threshold


def test_a_cell_beside_an_obstacle_exports_white_only_when_all_of_it_was_seen_free() -> None:
    """The tip of a turned desk or an ellipse pokes a few centimetres into the next map cell, where
    no beam reaches it without touching the obstacle: the rest of that cell is seen free. In the
    exported map a cell beside a black one needs every evidence cell free to be white; elsewhere
    nearly all (``white_min_free``) will do."""
    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(0.5, 0.5, 0.0), extent=(0.0, 0.0, 2.0, 2.0))

    def exported(beside: float) -> tuple[np.ndarray, np.ndarray]:
        params = LogOddsParams(final_occlusion=False, white_min_free=0.9, white_min_free_beside=beside)
        mapper = make_mapper("logodds", frame, ROBOT, SlamConfig(logodds=params))
        assert isinstance(mapper, LogOddsMapper)
        k = mapper.k
        inner = mapper.free_evidence[mapper._inner]  # a view: one evidence cell per k x k block
        inner[:] = -5.0
        row, col = (int(v) for v in grid.world_to_index(1.1, 1.1))
        mapper.contact_evidence[mapper._inner][row * k + 1, col * k + 1] = 5.0  # an obstacle in (row, col)
        inner[row * k + 1, col * k + 1] = 0.0
        for r, c in ((row, col + 1), (row + 4, col)):  # a cell beside it and one away, each with one blind spot
            inner[r * k + 1, c * k] = 0.0
        mapper._changed()
        live = mapper.states()
        mapper.finalize()
        return live, mapper.states()

    row, col = (int(v) for v in grid.world_to_index(1.1, 1.1))
    live, final = exported(beside=1.0)
    assert live[row, col] == OCCUPIED and final[row, col] == OCCUPIED
    assert live[row, col + 1] == FREE  # while exploring, nearly all of it seen free will do ...
    assert final[row, col + 1] == UNKNOWN  # ... but not in the finished map
    assert live[row + 4, col] == FREE and final[row + 4, col] == FREE  # away from obstacles it will
    assert exported(beside=0.9)[1][row, col + 1] == FREE


def test_a_free_cell_between_two_black_ones_is_black_in_the_finished_map_at_fine_resolution() -> None:
    """At 0.1 m a beam that grazes an obstacle's face, and hears nothing from it, clears one cell of
    its outline, and the free floor then runs into the obstacle's inside. In the finished map, when a
    cell is narrower than the robot, a free cell between two black ones in a row or a column is
    black, except where the robot's body has been."""

    def final_map(
        fill_gaps: bool, resolution: float = 0.1, body_at: tuple[float, float] | None = None
    ) -> tuple[np.ndarray, int, int]:
        """The finished map, and the row and column of the gap cell at (1.05, 1.05)."""
        g = GridSpec(0.0, 0.0, resolution, round(2.0 / resolution), round(2.0 / resolution))
        params = LogOddsParams(final_occlusion=False, fill_gaps=fill_gaps)
        frame = MapFrame(grid=g, start=Pose(0.5, 0.5, 0.0), extent=(0.0, 0.0, 2.0, 2.0))
        mapper = make_mapper("logodds", frame, ROBOT, SlamConfig(logodds=params))
        assert isinstance(mapper, LogOddsMapper)
        k = mapper.k
        mapper.free_evidence[mapper._inner][:] = -5.0
        row, col = (int(v) for v in g.world_to_index(1.05, 1.05))
        for c in (col - 1, col + 1):  # black on either side of (row, col), a gap in an outline
            mapper.contact_evidence[mapper._inner][row * k, c * k] = 9.0
        if body_at is not None:
            mapper.mark_body(Pose(*body_at, 0.0))
        mapper._changed()
        mapper.finalize()
        return mapper.states(), row, col

    kept, row, col = final_map(fill_gaps=False)
    assert kept[row, col] == FREE
    filled, _, _ = final_map(fill_gaps=True)
    assert filled[row, col] == OCCUPIED
    assert filled[row, col - 1] == OCCUPIED and filled[row, col + 1] == OCCUPIED
    assert filled[row + 1, col] == FREE and filled[row, col + 3] == FREE  # nothing else changes
    # Where the robot's body has been, the floor is free.
    assert final_map(fill_gaps=True, body_at=(1.05, 1.05))[0][row, col] == FREE
    # At 0.2 m a cell is wider than the robot, and a one-cell gap may be a way through.
    coarse, r2, c2 = final_map(fill_gaps=True, resolution=0.2)
    assert coarse[r2, c2] == FREE


def test_echoes_off_the_room_box_are_explained_by_its_wall() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(0.4, 1.0, 0.0), extent=(0.0, 0.0, 2.0, 2.0))

    def evidence_inside_and_beyond(boundary_support: float) -> tuple[float, float]:
        params = LogOddsParams(boundary_support=boundary_support)
        mapper = make_mapper("logodds", frame, ROBOT, SlamConfig(logodds=params))
        assert isinstance(mapper, LogOddsMapper)
        for y in np.arange(0.6, 1.45, 0.1):  # the box's right wall at x = 2, seen from 1.6 m
            pose = Pose(0.4, float(y), 0.0)
            mapper.integrate(pose, _front_echo_to(2.0, pose))
        mapper.finalize()
        occ = mapper.occupied_evidence()
        xs, _ = mapper.fine.centers()
        beyond = xs + mapper.fine.resolution / 2 > 2.0 + 1e-9  # reaching past the right wall
        return float(occ[~beyond].sum()), float(occ[beyond].sum())

    inside, beyond = evidence_inside_and_beyond(5.0)
    inside_alone, beyond_alone = evidence_inside_and_beyond(0.0)
    # The arcs' off-axis cells fall inside the room; with the wall as support they give way to it.
    assert inside < 0.25 * inside_alone
    assert beyond > beyond_alone


def test_the_log_odds_map_does_not_depend_on_when_it_is_read() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=(0.0, 0.0, 2.0, 2.0))
    rng = np.random.default_rng(3)
    sweeps = [(Pose(*rng.uniform(0.5, 1.5, 2), rng.uniform(-3, 3)), rng.uniform(0.1, 2.0, 8)) for _ in range(30)]
    a = make_mapper("logodds", frame, ROBOT, SlamConfig())
    b = make_mapper("logodds", frame, ROBOT, SlamConfig())
    for i, (pose, ranges) in enumerate(sweeps):
        a.integrate(pose, ranges)
        b.integrate(pose, ranges)
        if i % 3 == 0:
            b.states()  # an extra look at b only
    assert np.array_equal(a.states(), b.states())


@pytest.mark.parametrize("resolution", [0.05, 0.1, 0.2, 1.0])
def test_map_cells_count_their_evidence_cells_like_the_block_means(resolution: float) -> None:
    # One evidence cell per map cell (0.05 m) up to 400 (1.0 m, more than a byte holds).
    grid = GridSpec(0.0, 0.0, resolution, round(2.0 / resolution), round(2.0 / resolution))
    frame = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=(0.0, 0.0, 1.9, 2.0))
    mapper = make_mapper("logodds", frame, ROBOT, SlamConfig(resolution=resolution))
    assert isinstance(mapper, LogOddsMapper)
    rng = np.random.default_rng(5)
    for _ in range(20):
        mapper.integrate(Pose(*rng.uniform(0.5, 1.5, 2), rng.uniform(-3, 3)), rng.uniform(0.1, 2.0, 8))
    fine, k = mapper.fine_states(), mapper.k
    blocks = fine.reshape(grid.rows, k, grid.cols, k)
    outside = mapper._fine_outside.reshape(grid.rows, k, grid.cols, k)
    some_occupied = ((blocks == OCCUPIED) & ~outside).any(axis=(1, 3))
    free_share = ((blocks == FREE) | outside).mean(axis=(1, 3))
    expected = np.full(grid.shape, UNKNOWN, dtype=np.int8)
    expected[(free_share >= 0.9) & ~mapper._outside] = FREE
    expected[some_occupied | mapper._outside] = OCCUPIED
    assert np.array_equal(mapper.states(), expected)
    occupied = (blocks == OCCUPIED).any(axis=(1, 3)) | mapper._outside
    assert np.array_equal(mapper.free_fraction(), np.where(occupied, -1.0, (blocks == FREE).mean(axis=(1, 3))))
    # One mask alone is counted as a stack of one.
    assert np.array_equal(mapper._block_counts(fine == FREE), (blocks == FREE).sum(axis=(1, 3)))


def test_classify_reads_the_belief_like_the_ground_truth() -> None:
    belief = np.array(
        [
            [OCCUPIED, OCCUPIED, OCCUPIED, UNKNOWN],
            [FREE, FREE, OCCUPIED, FREE],
            [FREE, UNKNOWN, OCCUPIED, FREE],
        ],
        dtype=np.int8,
    )
    exported = classify(belief, (1, 0))
    expected = np.array([[1, 1, 1, -1], [0, 0, 1, -1], [0, 1, 1, -1]], dtype=np.int8)
    assert np.array_equal(exported, expected)


def test_cells_the_robot_drove_into_against_the_map_connect_the_exported_map_and_stay_black() -> None:
    """Echo arcs smeared across a narrow gap leave it occupied in the belief after the robot has
    driven through; the room beyond is still reachable."""
    belief = np.array(
        [
            [FREE, OCCUPIED, FREE, FREE],
            [FREE, OCCUPIED, FREE, FREE],
            [FREE, OCCUPIED, FREE, FREE],
        ],
        dtype=np.int8,
    )
    cut_off = classify(belief, (1, 0))
    assert (cut_off[:, 2:] == UNKNOWN).all()
    passages = np.zeros(belief.shape, dtype=bool)
    passages[1, 1] = True  # the robot drove through the gap at (1, 1)
    exported = classify(belief, (1, 0), passages)
    assert (exported[:, 2:] == FREE).all() and (exported[:, 0] == FREE).all()
    assert (exported[:, 1] == OCCUPIED).all()


# -- exploration -------------------------------------------------------------------------------
def test_neighbours_are_tried_clockwise_starting_from_the_heading() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 5, 5)
    explorer = Explorer(grid, 1, (2, 2))
    free = np.ones(grid.shape)
    states = np.zeros(grid.shape, dtype=np.int8)
    first = explorer.decide((2, 2), math.radians(0.0), states, states == FREE, free)  # facing east
    assert first.kind == "move" and first.target == (2, 3)
    assert CLOCKWISE[direction_index(math.radians(0.0))] == (0, 1)
    second = explorer.decide((2, 3), math.radians(0.0), states, states == FREE, free)
    assert second.target == (2, 4)


def test_a_dead_end_backtracks_to_the_cell_it_came_from() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 3, 3)
    explorer = Explorer(grid, 1, (1, 0))
    free = np.full(grid.shape, -1.0)
    free[1, :] = 1.0  # a one-cell corridor along row 1
    states = np.where(free > 0, FREE, OCCUPIED).astype(np.int8)
    assert explorer.decide((1, 0), 0.0, states, free > 0, free).target == (1, 1)
    assert explorer.decide((1, 1), 0.0, states, free > 0, free).target == (1, 2)
    back = explorer.decide((1, 2), 0.0, states, free > 0, free)
    assert back.kind == "move" and back.target == (1, 1) and back.reason == "backtrack"


def test_a_robot_boxed_in_by_its_own_map_retries_the_cells_it_has_stood_in() -> None:
    # The robot explored into the corner (4, 0) from (3, 1); since then the map shows a wall
    # clipping (3, 0) and (3, 1), and the move back east to (4, 1) bumped. Rows 0-2 are unexplored.
    grid = GridSpec(0.0, 0.0, 0.2, 5, 5)
    free = np.ones(grid.shape)
    free[3, 0] = free[3, 1] = -1.0
    states = np.where(free > 0, FREE, OCCUPIED).astype(np.int8)

    def boxed_in(max_escapes: int) -> Explorer:
        explorer = Explorer(grid, 1, (3, 1), max_escapes=max_escapes)
        explorer.visited[3, 1] = explorer.visited[4, 1] = True
        explorer.bumped[4, 1] = True
        return explorer

    explorer = boxed_in(max_escapes=5)
    action = explorer.decide((4, 0), 0.0, states, free > 0, free)
    # A first step into a cell is free of charge (see the slot test below).
    assert action.kind == "move" and action.target == (3, 1) and explorer.escapes == 0
    # Without escapes the same robot ends the run with most of the room unexplored, and says why.
    ended = boxed_in(max_escapes=0).decide((4, 0), 0.0, states, free > 0, free)
    assert ended.kind == "done" and ended.reason == "boxed_in"
    # Escapes are bounded: a robot that keeps bumping out of the corner ends in the end. Each retry
    # of the same cell counts.
    explorer = boxed_in(max_escapes=2)
    actions = []
    for _ in range(6):
        action = explorer.decide((4, 0), 0.0, states, free > 0, free)
        actions.append(action.kind)
        if action.kind == "done":
            break
        explorer.bumped[action.target] = True  # the move failed; the robot is back in the corner
    assert actions == ["move", "move", "move", "done"] and explorer.escapes == 2
    assert action.reason == "boxed_in"
    # A run that has simply finished, with every place it has been still in reach, does not escape.
    done = Explorer(grid, 1, (0, 0))
    done.visited[:, :] = True
    done.bumped[0, 4] = True
    finished = done.decide((0, 0), 0.0, states, free > 0, free)
    assert finished.kind == "done" and finished.reason == "complete" and done.escapes == 0


def test_a_robot_backs_out_of_a_long_slot_its_map_has_closed_whatever_the_escape_budget() -> None:
    # The robot drove down a slot one cell wide along column 0 into its dead end at (6, 0); since
    # then the map holds every cell of the slot occupied (echo arcs smeared across it). The room it
    # came from (row 0) and the unexplored floor beyond (columns 2-3) are open.
    grid = GridSpec(0.0, 0.0, 0.2, 7, 4)
    free = np.ones(grid.shape)
    free[1:, 0] = free[1:, 1] = -1.0  # the slot, closed in the map, and the furniture beside it
    states = np.where(free > 0, FREE, OCCUPIED).astype(np.int8)
    states[3:, 2:] = UNKNOWN
    free[3:, 2:] = 0.0
    explorer = Explorer(grid, 1, (0, 0), max_escapes=2)
    explorer.visited[0, :] = explorer.visited[:, 0] = True
    cell = (6, 0)
    path = []
    for _ in range(10):
        action = explorer.decide(cell, math.pi / 2, states, free > 0, free)
        if action.kind != "move" or action.target is None or action.target[1] != 0:
            break
        cell = action.target
        path.append(cell)
    # Six steps back up the slot, each into a cell not escaped to before: none counts.
    assert path == [(5, 0), (4, 0), (3, 0), (2, 0), (1, 0), (0, 0)]
    assert explorer.escapes == 0
    # Out of the slot, the robot heads for the unexplored floor on its own.
    assert action.kind == "move" and action.target is not None and action.target[1] >= 1


def test_a_settled_map_sends_the_robot_to_the_frontier_instead_of_on_through_explored_floor() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 5, 8)
    states = np.full(grid.shape, FREE, dtype=np.int8)
    states[:, 7] = UNKNOWN  # the far end, not seen yet
    free_fraction = np.where(states == FREE, 1.0, 0.0)
    passable = states == FREE
    explorer = Explorer(grid, 1, (2, 1))
    walk = explorer.decide((2, 1), math.pi / 2, states, passable, free_fraction)
    assert walk.kind == "move" and walk.target == (1, 1) and walk.reason == "explore"  # depth-first: north
    seek = Explorer(grid, 1, (2, 1))
    action = seek.decide((2, 1), math.pi / 2, states, passable, free_fraction, seek_frontier=True)
    assert action.kind == "move" and action.target is not None and action.reason == "frontier"
    assert action.target[1] == 2 and not seek.stack  # a step east, off the depth-first walk
    here = (2, 1)
    while here[1] < 6:  # straight there, one cell east a step
        assert action.kind == "move" and action.target is not None and action.target[1] == here[1] + 1
        here = action.target
        action = seek.decide(here, 0.0, states, passable, free_fraction, seek_frontier=True)
    assert here[1] == 6  # next to the frontier; on along it, to cells not stood in yet
    assert action.kind == "move" and action.target is not None and action.reason == "frontier"
    assert action.target[1] == 6 and not seek.visited[action.target]
    # Once the robot has stood in every cell next to it, it looks from where it is.
    seek.visited[:, 6] = True
    look = seek.decide(here, 0.0, states, passable, free_fraction, seek_frontier=True)
    assert look.kind == "inspect" and look.heading_rad is not None and abs(math.cos(look.heading_rad)) > 0.7
    # With nothing left to resolve, seeking falls back to the depth-first walk.
    states[:, 7] = OCCUPIED
    free_fraction[:, 7] = -1.0
    again = seek.decide(here, 0.0, states, states == FREE, free_fraction, seek_frontier=True)
    assert again.kind == "move" and again.reason == "explore"


def test_a_settled_map_gives_up_unknown_cells_it_has_closed_off_instead_of_walking_on() -> None:
    """A pillar's inside stayed unknown, next to a cell the robot had stood in before the map found
    the pillar there: no cell beside it could be reached, and the hall's seed 4 walked on until the
    20-minute time limit."""
    grid = GridSpec(0.0, 0.0, 0.2, 5, 8)
    states = np.full(grid.shape, FREE, dtype=np.int8)
    states[1:4, 4:7] = OCCUPIED
    states[2, 5] = UNKNOWN  # the pillar's inside
    free_fraction = np.where(states == FREE, 1.0, -1.0)
    passable = states == FREE

    def settled() -> Explorer:
        explorer = Explorer(grid, 1, (2, 1))
        explorer.visited[:, :4] = True
        explorer.visited[2, 4] = True  # stood in before it was found occupied
        return explorer

    explorer = settled()
    assert explorer.frontier(states, passable)[2, 5]
    action = explorer.decide((2, 1), 0.0, states, passable, free_fraction, seek_frontier=True, give_up_closed=True)
    assert action.reason != "frontier" and (2, 5) in explorer.given_up
    assert not explorer.frontier(states, passable).any()
    # Settled for less time, or walking on depth-first, the robot keeps the cell to resolve.
    for seek in (True, False):
        walking = settled()
        walking.decide((2, 1), 0.0, states, passable, free_fraction, seek_frontier=seek)
        assert not walking.given_up
    # A robot cut off from where it has been (here by a bump on each side) keeps it too.
    boxed = settled()
    boxed.bumped[1:4, 0:3] = True
    boxed.bumped[2, 1] = False
    boxed.decide((2, 1), 0.0, states, passable, free_fraction, seek_frontier=True, give_up_closed=True)
    assert not boxed.given_up


def _room_with_a_closed_gap() -> tuple[
    GridSpec, NDArray[np.float64], NDArray[np.int8], NDArray[np.bool_], NDArray[np.bool_]
]:
    """Row 2 runs from an explored room (columns 0-1) through a gap at (2, 2) that echoes closed, on
    to floor seen free beyond (columns 3-5), walled off everywhere else: the grid, its free
    fractions, states, passable cells and echoed cells (nothing bumped, nothing past the room box)."""
    grid = GridSpec(0.0, 0.0, 0.2, 5, 6)
    free_fraction = np.full(grid.shape, -1.0)
    free_fraction[:, 0:2] = 1.0
    free_fraction[2, 3:6] = 1.0
    states = np.where(free_fraction >= 0.0, FREE, OCCUPIED).astype(np.int8)
    return grid, free_fraction, states, states == FREE, states == OCCUPIED


def test_a_cell_only_echoes_hold_occupied_is_probed_when_free_floor_lies_beyond_it() -> None:
    """The room of ``_room_with_a_closed_gap``: a gap the echoes closed, free floor beyond it."""
    grid, free_fraction, states, passable, echoed = _room_with_a_closed_gap()
    explorer = Explorer(grid, 1, (2, 0), probe_min_cells=3)
    explorer.visited[:, 0:2] = True
    trav = explorer.traversable(free_fraction)
    # Three cells beyond are a pocket behind furniture by default, a room to probe for at 3.
    assert Explorer(grid, 1, (2, 0)).probe_min_cells > 3
    assert Explorer(grid, 1, (2, 0)).probe((2, 1), trav, echoed, free_fraction) is None
    # From beside the gap: drive into it. From (0, 0): first a step towards (2, 1), beside it.
    assert explorer.probe((2, 1), trav, echoed, free_fraction) == ((2, 2), (2, 2))
    assert explorer.probe((0, 0), trav, echoed, free_fraction) == ((1, 1), (2, 2))
    action = explorer.decide((2, 1), 0.0, states, passable, free_fraction, probe_cells=echoed)
    assert action.kind == "move" and action.target == (2, 2) and action.reason == "probe"
    assert explorer.probed == {(2, 2)}
    assert not explorer.passages().any()  # not until the robot is in it
    explorer.visited[2, 2] = True
    assert explorer.passages()[2, 2] and explorer.passages().sum() == 1
    # Once probed (or bumped), or where a bump or the room box holds it, or with probes spent,
    # there is nothing to probe, and the run is done.
    assert explorer.probe((2, 1), trav, echoed, free_fraction) is None
    for change in ("bumped", "not_echoed", "spent"):
        other = Explorer(grid, 1, (2, 0), max_probes=0 if change == "spent" else 8, probe_min_cells=3)
        other.visited[:, 0:2] = True
        cells = echoed.copy()
        if change == "bumped":
            other.bumped[2, 2] = True
        if change == "not_echoed":
            cells[2, 2] = False
        assert other.probe((2, 1), other.traversable(free_fraction), cells, free_fraction) is None
        done = other.decide((2, 1), 0.0, states, passable, free_fraction, probe_cells=cells)
        assert done.kind == "done"
    # Floor beyond that the robot can already reach (here round by rows 3-4) is no reason to probe.
    free_fraction[3:5, :] = 1.0
    reachable = Explorer(grid, 1, (2, 0), probe_min_cells=3)
    assert reachable.probe((2, 1), reachable.traversable(free_fraction), echoed, free_fraction) is None


def test_a_cell_the_beams_from_beside_it_saw_through_is_probed_towards_unknown_space() -> None:
    """Row 2 of ``_room_with_a_closed_gap``, with nothing seen beyond the gap: the cell (2, 2), held
    occupied by echoes or not seen at all, closes off unknown space. It is probed once two beams
    along row 2 from (2, 1) heard no echo and none heard one within 2.5 cells; after one such beam
    the robot turns along the row and looks again first."""
    grid, free_fraction, states, passable, echoed = _room_with_a_closed_gap()
    free_fraction[2, 3:6] = 0.0  # unknown beyond
    states[2, 3:6] = UNKNOWN
    for held in ("echoes", "nothing"):
        cells = echoed.copy()
        ff = free_fraction.copy()
        if held == "nothing":
            cells[2, 2] = False
            ff[2, 2] = 0.1
        explorer = Explorer(grid, 1, (2, 0))
        explorer.visited[:, 0:2] = True
        trav = explorer.traversable(ff)
        x, y = explorer.nav_center((2, 1))
        assert explorer.probe((2, 1), trav, cells, ff) is None  # nothing heard yet
        # A beam 15 degrees off the row does not look along it; one along it that heard nothing does,
        # but one beam may be a dropout: the robot looks again along the row first.
        explorer.note_view(x, y, [math.radians(15.0)], [math.inf])
        assert explorer.probe((2, 1), trav, cells, ff) is None
        explorer.note_view(x, y, [math.radians(4.0)], [math.inf])
        assert explorer.probe((2, 1), trav, cells, ff) == ((2, 2), (2, 2))
        assert explorer.pending_look == ((2, 1), 2)
        assert explorer.probe((2, 1), trav, cells, ff, see_through=False) is None
        assert explorer.probe((0, 0), trav, cells, ff) == ((1, 1), (2, 2))  # on the way to look
        look = explorer.decide((2, 1), 0.0, states, passable, ff, probe_cells=cells)
        assert look.kind == "inspect" and look.reason == "probe" and look.heading_rad == pytest.approx(0.0)
        assert explorer.probed == set()
        explorer.note_view(x, y, [0.0], [math.inf])  # the look heard nothing either
        assert explorer.probe((2, 1), trav, cells, ff) == ((2, 2), (2, 2)) and explorer.pending_look is None
        action = explorer.decide((2, 1), 0.0, states, passable, ff, probe_cells=cells)
        assert action.kind == "move" and action.target == (2, 2) and action.reason == "probe"
        assert explorer.probe((2, 1), trav, cells, ff) is None  # probed once
        # A look that hears an echo within 2.5 cells ends it; one past the cell neither opens nor
        # shuts it (space already mapped), and no cell is looked at twice.
        shut = Explorer(grid, 1, (2, 0))
        shut.visited[:, 0:2] = True
        shut.note_view(x, y, [0.0], [0.55])
        assert shut.probe((2, 1), trav, cells, ff) is None
        shut.note_view(x, y, [0.0], [math.inf])
        assert shut.decide((2, 1), 0.0, states, passable, ff, probe_cells=cells).kind == "inspect"
        shut.note_view(x, y, [0.0], [0.45])
        assert shut.probe((2, 1), trav, cells, ff) is None
        shut.views_shut[:] = 0
        assert shut.probe((2, 1), trav, cells, ff) is None  # looked once already
    # Unknown space the robot can already get to some other way is no reason to probe.
    free_fraction[3:5, :] = 1.0
    reachable = Explorer(grid, 1, (2, 0))
    reachable.visited[:, 0:2] = True
    reachable.note_view(*reachable.nav_center((2, 1)), [0.0], [math.inf])
    assert reachable.probe((2, 1), reachable.traversable(free_fraction), echoed, free_fraction) is None


def test_a_corridor_narrowed_by_a_round_bin_is_probed_and_mapped_past_it() -> None:
    """A 1.25 m corridor with a 60 cm bin 25 cm off its bottom wall: both gaps are a cell wide, the
    corridor beyond is more than the sonar's range long, so the beams through the gaps hear nothing
    and clear nothing, and an arc's corner closed the gaps in the map. The run ended with the
    corridor past the bin grey (F1 0.80)."""
    world = world_from_dict(
        {
            "name": "binned-corridor",
            "boundary": [[9.4, 1.25], [9.4, 0.0], [0.0, 0.0], [0.0, 1.25], [0.85, 1.25], [0.85, 2.25],
                         [2.25, 2.25], [2.25, 1.25]],
            "start": {"x": 1.6, "y": 0.4, "theta_deg": 0.0},
            "obstacles": [{"shape": "circle", "center": [4.75, 0.55], "radius": 0.3}],
        },
        "binned-corridor.toml",
    )  # fmt: skip
    cfg = load_run_config()
    result = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    assert max(row[4] for row in result.trajectory) > 8.0  # past the bin, to the corridor's end
    assert result.terminated_by == "complete"
    assert result.metrics.f1 >= 0.95


def test_a_settled_robot_heads_for_a_gap_to_probe_before_walking_on_depth_first() -> None:
    """The room of the test above, with one explored cell not yet stood in. Walking depth-first the
    robot steps there first (and, in a large room, on through the rest of it for minutes); once the
    map has settled with nothing else left to resolve, it drives into the gap instead."""
    grid, free_fraction, states, passable, echoed = _room_with_a_closed_gap()

    def explorer() -> Explorer:
        e = Explorer(grid, 1, (2, 0), probe_min_cells=3)
        e.visited[:, 0:2] = True
        e.visited[1, 0] = False
        return e

    walking = explorer().decide((2, 1), 0.0, states, passable, free_fraction, probe_cells=echoed)
    assert walking.kind == "move" and walking.target == (1, 0) and walking.reason == "explore"
    settled = explorer()
    action = settled.decide((2, 1), 0.0, states, passable, free_fraction, seek_frontier=True, probe_cells=echoed)
    assert action.kind == "move" and action.target == (2, 2) and action.reason == "probe"
    assert settled.probed == {(2, 2)}
    # With no gap to probe, a settled robot walks on as before.
    nothing = explorer().decide((2, 1), 0.0, states, passable, free_fraction, seek_frontier=True)
    assert nothing.target == (1, 0) and nothing.reason == "explore"


def test_a_doorway_narrowed_by_furniture_is_probed_and_the_room_beyond_mapped() -> None:
    """A partition's 95 cm doorway, a desk leaving 37.5 cm of it: echo arcs closed the gap in the
    map, and the run ended with the room beyond unseen (F1 0.38). (Seed 4 still ends so: its beams
    through the gap hear echoes from beyond it, and too little floor there was seen free.)"""
    world = world_from_dict(
        {
            "name": "narrowed-door",
            "boundary": [[6.7, 0.0], [6.7, 3.8], [0.0, 3.8], [0.0, 0.0]],
            "start": {"x": 2.7, "y": 2.3, "theta_deg": -90.0},
            "obstacles": [
                {"shape": "rect", "center": [3.5, 0.9], "size": [0.1, 1.8]},
                {"shape": "rect", "center": [3.5, 3.275], "size": [0.1, 1.05]},
                {"shape": "rect", "center": [3.8, 2.05], "size": [1.1, 0.65]},
                {"shape": "rect", "center": [5.05, 2.25], "size": [0.75, 0.65]},
            ],
        },
        "narrowed-door.toml",
    )
    cfg = load_run_config()
    result = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    assert result.terminated_by == "complete"
    assert result.metrics.f1 >= 0.95
    # Without probing, the same run leaves the far room grey.
    cfg_off = load_run_config(None, {"max_probes": 0})
    assert simulate(world, cfg_off.robot, cfg_off.noise, cfg_off.slam, seed=0).metrics.f1 < 0.6


def test_a_robot_that_explored_down_a_slot_behind_a_cabinet_backs_out_and_maps_the_room() -> None:
    """A cabinet 17 cm from the right wall, and a desk at the slot's far end leaving 20 cm: at 0.1 m
    the robot explores down the slot; its map then closes the slot's cells behind it, and backing out
    took one escape per cell. The budget of five ran out in the slot and the run ended with most of
    the room unseen (F1 0.54 after 129 steps)."""
    world = world_from_dict(
        {
            "name": "slot",
            "boundary": [[4.4, 0.0], [4.4, 4.45], [0.0, 4.45], [0.0, 0.0]],
            "start": {"x": 2.6, "y": 2.6, "theta_deg": 0.0},
            "obstacles": [
                {"shape": "rect", "center": [1.875, 0.1], "size": [1.95, 0.3]},
                {"shape": "rect", "center": [3.818, 1.875], "size": [0.825, 1.75]},
                {"shape": "rect", "center": [1.15, 3.5], "size": [0.55, 0.65]},
                {"shape": "rect", "center": [3.55, 0.515], "size": [1.3, 0.65]},
            ],
        },
        "slot.toml",
    )
    cfg = load_run_config(None, {"resolution": 0.1})
    result = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    true_xy = [(row[4], row[5]) for row in result.trajectory]
    in_slot = [i for i, (x, y) in enumerate(true_xy) if x > 4.23 and y < 1.0]
    assert in_slot, "the robot no longer explores the slot: the test does not test the escape"
    assert any(x < 3.0 for x, _ in true_xy[in_slot[-1] :])  # out of the slot and on across the room
    assert result.terminated_by == "complete"
    assert result.metrics.f1 >= 0.9


def test_a_boxed_in_robot_first_steps_off_sideways_and_retries_its_moves() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 5, 5)
    free = np.ones(grid.shape)
    free[3, 0] = free[3, 1] = -1.0
    states = np.where(free > 0, FREE, OCCUPIED).astype(np.int8)
    explorer = Explorer(grid, 1, (3, 1), max_escapes=1, max_unpins=1)
    explorer.visited[3, 1] = explorer.visited[4, 1] = True
    explorer.bumped[4, 1] = explorer.bumped[3, 1] = True
    explorer.escapes = 1  # spent
    action = explorer.decide((4, 0), 0.0, states, free > 0, free)
    # Instead of ending the run: a side step, then the failed moves are worth trying again.
    assert action.kind == "unpin" and explorer.unpins == 1
    assert not explorer.bumped.any() and explorer.escapes == 0 and not explorer.given_up
    retry = explorer.decide((4, 0), 0.0, states, free > 0, free)
    assert retry.kind == "move"
    # Once the side steps are spent too, the run ends boxed in as before.
    explorer.bumped[4, 1] = explorer.bumped[3, 1] = True
    explorer.escapes = 1
    ended = explorer.decide((4, 0), 0.0, states, free > 0, free)
    assert ended.kind == "done" and ended.reason == "boxed_in"


def test_a_robot_pinned_against_a_wardrobe_in_a_slot_steps_off_and_maps_the_room() -> None:
    """A wardrobe 17 cm from the top wall; the robot explores along the slot with a centimetre to
    spare, its estimate a centimetre off across it, so each move west heads a fraction of a degree
    into the wardrobe and stalls. The run ended boxed in after 52 steps with most of the room unseen
    (F1 0.43)."""
    world = world_from_dict(
        {
            "name": "wardrobe-slot",
            "boundary": [[4.45, 0.0], [4.45, 4.6], [0.0, 4.6], [0.0, 0.0]],
            "start": {"x": 1.1, "y": 1.65, "theta_deg": 68.0},
            "obstacles": [
                {"shape": "polygon", "points": [[0.0, 0.0], [0.63, 0.0], [0.0, 0.46]]},
                {"shape": "ellipse", "center": [0.8, 0.1], "radii": [0.25, 0.2], "angle_deg": -15.0},
                {"shape": "rect", "center": [3.7, 4.005], "size": [1.4, 0.85]},
            ],
        },
        "wardrobe-slot.toml",
    )
    cfg = load_run_config()
    actions: list[str] = []
    result = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0, on_step=lambda s: actions.append(s.action))
    assert "unpin" in actions, "the robot is no longer pinned: the test does not test the side step"
    assert result.terminated_by == "complete"
    assert result.metrics.f1 >= 0.9
    # Without the side step the same run ends boxed in.
    cfg_off = load_run_config(None, {"max_unpins": 0})
    pinned = simulate(world, cfg_off.robot, cfg_off.noise, cfg_off.slam, seed=0)
    assert pinned.terminated_by == "boxed_in" and pinned.metrics.f1 < 0.6


def test_a_far_arm_of_a_large_room_is_mapped_although_the_near_one_settles_long_before() -> None:
    """Walking the explored 4 x 5.4 m arm depth-first cell by cell took longer than the time limit,
    and the run ended with the far half of the 7.5 m arm unseen (F1 0.78)."""
    world = world_from_dict(
        {
            "name": "wide-l",
            "boundary": [[7.45, 0.0], [0.0, 0.0], [0.0, 5.35], [4.0, 5.35], [4.0, 3.0], [7.45, 3.0]],
            "start": {"x": 3.4, "y": 3.95, "theta_deg": 90.0},
        },
        "wide-l.toml",
    )
    cfg = load_run_config()
    result = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    assert result.terminated_by == "complete"
    assert result.metrics.f1 >= 0.97


def test_config_refuses_settings_that_cannot_work(tmp_path: Path) -> None:
    # A setting given on the command line is named as given, not blamed on the default file.
    with pytest.raises(ConfigError, match=r"^resolution = 0.03: resolution 0.03 m is finer than the evidence grid"):
        load_run_config(None, {"resolution": 0.03})
    user = tmp_path / "fine.toml"
    user.write_text("[slam]\nresolution = 0.03\n")
    with pytest.raises(ConfigError) as refused:
        load_run_config(user)
    assert str(refused.value).startswith(f"{user}: resolution 0.03 m is finer than the evidence grid")
    assert "Value error" not in str(refused.value) and "top level" not in str(refused.value)
    with pytest.raises(ConfigError, match="smaller than the robot"):
        load_run_config(None, {"resolution": 0.05, "nav_cell_min_m": 0.05})


@pytest.mark.parametrize(
    ("table", "key", "value"),
    [
        ("motion", "tick_s", 1e-6),  # a control loop of a million ticks a second never finishes a move
        ("logodds.tangents", "theta_step_deg", 1e-6),  # a wall accumulator of tens of gigabytes
        ("logodds.tangents", "d_step_m", 1e-6),
    ],
)
def test_config_refuses_settings_that_would_hang_or_exhaust_memory(tmp_path, table: str, key: str, value: float):
    path = tmp_path / "slam.toml"
    path.write_text(f"[slam.{table}]\n{key} = {value}\n")
    with pytest.raises(ConfigError, match=rf"{table}\.{key}: Input should be greater than or equal to"):
        load_run_config(path, {})


# -- the engine --------------------------------------------------------------------------------
def test_an_exact_robot_maps_a_small_room_and_says_why_it_stopped() -> None:
    world = small_world([{"shape": "rect", "center": [1.3, 0.9], "size": [0.4, 0.3], "angle_deg": 0.0}])
    cfg = load_run_config()
    result = simulate(world, cfg.robot, SimNoise.off(), cfg.slam, seed=0)
    assert result.terminated_by == "complete"
    # 80 cells of which only 9 are non-vacant: a handful of wrong cells next to the walls at most.
    assert result.metrics.recall >= 0.95
    assert result.metrics.cell_errors <= 4
    assert result.final_xy_error_m < 0.02


def small_engine(world, seed: int) -> SlamEngine:
    """The default engine on a simulated ``world`` with the default noise."""
    from robot.sim import SimRobot

    cfg = load_run_config()
    sim = SimRobot(world, cfg.robot, SimNoise(), seed=seed)
    return SlamEngine(sim, cfg.robot, cfg.slam, frame_for_world(world, 0.2))


def test_step_deltas_rebuild_the_exported_map() -> None:
    world = small_world()
    engine = small_engine(world, seed=4)
    rebuilt = np.full(engine.map_states().shape, UNKNOWN, dtype=np.int8)
    steps = 0
    while not engine.done:
        step = engine.step()
        rebuilt[step.changed_rows, step.changed_cols] = step.changed_states
        steps += 1
        assert steps < 2000
    assert np.array_equal(rebuilt, engine.map_states())
    _, truth = truth_grid(world, 0.2)
    assert score(rebuilt, truth).cell_errors <= 3  # an empty 2 x 1.6 m room: 80 cells, all white


def test_lone_occupied_cells_are_those_in_free_floor() -> None:
    states = np.full((6, 7), FREE, dtype=np.int8)
    states[1, 1] = OCCUPIED  # alone
    states[3, 3:5] = OCCUPIED  # two together
    states[1, 5] = OCCUPIED  # next to unknown space
    states[0, 6] = UNKNOWN
    states[5, 0] = OCCUPIED  # on the grid's edge: what lies beyond is not known free
    lone = lone_occupied(states)
    assert lone.tolist() == (np.arange(42).reshape(6, 7) == 8).tolist()


def test_an_open_room_ends_once_it_is_mapped() -> None:
    """An empty room is mapped long before the depth-first walk has stood in every cell."""
    world = load_world("room1")
    cfg = load_run_config()
    walked = simulate(world, cfg.robot, cfg.noise, load_run_config(None, {"end_when_mapped": False}).slam, seed=0)
    mapped = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    assert walked.terminated_by == mapped.terminated_by == "complete"
    assert mapped.steps < walked.steps / 4
    assert mapped.metrics.f1 == walked.metrics.f1 == 1.0


def test_a_run_ends_early_only_on_a_settled_map_without_stray_cells() -> None:
    engine = small_engine(small_world(), seed=0)
    for _ in range(3):
        engine.step()
    belief = np.full(engine.map_states().shape, FREE, dtype=np.int8)
    belief[engine._outside] = OCCUPIED
    engine._belief = belief
    engine._last_change_step = engine.stats.steps - engine.config.settle_steps
    assert engine._mapped()
    engine._last_change_step += 1  # the map changed too recently
    assert not engine._mapped()
    engine._last_change_step -= 1
    belief[4, 5] = OCCUPIED  # a black cell alone in free floor
    assert not engine._mapped()
    # ... until the map has not changed for give_up_steps: the sweeps since have not cleared it, so
    # it is a chair leg (a clutter room walked on to the time limit, its map done 300 steps before).
    engine._last_change_step = engine.stats.steps - engine.config.give_up_steps
    assert engine._mapped()
    engine._last_change_step += 1
    assert not engine._mapped()
    belief[4, 5] = UNKNOWN  # an unresolved cell in reach
    assert not engine._mapped()


def test_stopping_early_keeps_the_partial_map() -> None:
    engine = small_engine(small_world(), seed=1)
    rebuilt = np.full(engine.map_states().shape, UNKNOWN, dtype=np.int8)
    for _ in range(5):
        step = engine.step()
        rebuilt[step.changed_rows, step.changed_cols] = step.changed_states
    final = engine.stop()
    rebuilt[final.changed_rows, final.changed_cols] = final.changed_states
    assert engine.done and engine.stats.terminated_by == "stopped"
    assert np.array_equal(rebuilt, engine.map_states())
    assert (rebuilt == FREE).sum() > 0


# -- position fixes from the room box ----------------------------------------------------------
def test_a_head_on_echo_off_a_box_wall_pulls_the_position_towards_the_truth() -> None:
    from robot.boxfix import BoxFixConfig

    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=(0.0, 0.0, 2.0, 2.0))
    true_x = 1.0
    believed = Pose(true_x + 0.04, 1.0, 0.0)  # dead reckoning is 4 cm too far east
    ranges = np.full(8, ROBOT.sonar.max_range_m)
    ranges[0] = 2.0 - true_x - ROBOT.sonars[0].offset_x_m  # the east wall, head on
    dx, dy = _box_fix(frame, ROBOT, believed, ranges, BoxFixConfig(gain=1.0))
    assert dx == pytest.approx(-0.04, abs=1e-9)
    assert dy == 0.0


def test_box_fixes_ignore_glancing_far_or_implausible_echoes_and_unknown_rooms() -> None:
    from robot.boxfix import BoxFixConfig

    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=(0.0, 0.0, 2.0, 2.0))
    ranges = np.full(8, ROBOT.sonar.max_range_m)
    ranges[0] = 0.5  # implies a wall at x = 1.56: furniture, not the box's wall
    assert _box_fix(frame, ROBOT, Pose(1.0, 1.0, 0.0), ranges, BoxFixConfig()) == (0.0, 0.0)
    ranges[0] = 2.0 - 1.0 - ROBOT.sonars[0].offset_x_m
    assert _box_fix(frame, ROBOT, Pose(1.0, 1.0, math.radians(10)), ranges, BoxFixConfig()) == (0.0, 0.0)
    unknown = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=None)
    assert _box_fix(unknown, ROBOT, Pose(1.0, 1.0, 0.0), ranges, BoxFixConfig()) == (0.0, 0.0)


def test_position_fixes_that_drift_across_the_travel_reveal_the_heading_error() -> None:
    from robot.headingfix import HeadingFixConfig, WallHeading

    rng = np.random.default_rng(7)
    delta = math.radians(1.0)  # the odometry's heading is off by a degree
    fits = WallHeading(HeadingFixConfig())
    # Driving north along the west wall, then east along the south wall: x-fixes and y-fixes.
    for y in np.arange(0.5, 4.5, 0.04):
        fits.add(0, 0.02 - delta * y + rng.normal(0.0, 0.01), 0.4, float(y))
    for x in np.arange(0.5, 4.5, 0.04):
        fits.add(1, -0.01 + delta * x + rng.normal(0.0, 0.01), float(x), 0.4)
    fits.add(0, 0.5, 0.4, 2.0)  # an echo off something else: rejected as an outlier
    fit = fits.fit()
    assert fit is not None and fit.fixes == 200
    assert math.degrees(fit.delta_rad) == pytest.approx(1.0, abs=0.15)
    assert fit.std_rad < math.radians(0.2)

    # Fixes along one wall alone measure it too.
    one_wall = WallHeading(HeadingFixConfig())
    for y in np.arange(0.5, 4.5, 0.02):
        one_wall.add(0, 0.02 - delta * y + rng.normal(0.0, 0.01), 0.4, float(y))
    fit = one_wall.fit()
    assert fit is not None and math.degrees(fit.delta_rad) == pytest.approx(1.0, abs=0.15)

    # Fixes from one place say nothing about the heading.
    still = WallHeading(HeadingFixConfig())
    for _ in range(200):
        still.add(0, 0.03 + rng.normal(0.0, 0.01), 0.4, 1.0)
    assert still.fit() is None


def test_a_heading_fix_corrects_the_filter_and_odometry_ignores_position_fixes() -> None:
    dr = DeadReckoning(ROBOT, Pose(1.0, 1.0, 0.0))
    dr.reset_origin(EncoderCounts(0.0, 0, 0))
    counts = 0
    for i in range(1, 201):  # two seconds forward: the filter's heading doubt grows with motion
        counts += 5
        dr.update(EncoderCounts(0.01 * i, counts, counts), [ImuSample(0.01 * i, 0.0)], wheels_commanded=True)
    before = dr.estimate
    dr.shift_position(0.05, -0.02)
    assert dr.odometry_xy == (before.x, before.y)
    after = dr.correct_heading(math.radians(2.0), math.radians(0.01))
    assert math.degrees(after.theta - before.theta) == pytest.approx(2.0, abs=0.05)
    assert after.theta_std < before.theta_std
    assert (after.x, after.y) == pytest.approx((before.x + 0.05, before.y - 0.02))


def _driven(fixes, metres: float) -> None:
    """Let ``fixes`` follow the estimate over ``metres`` of driving with no fix: the drift a bump
    may correct grows with it (``DriftGate``)."""
    fixes.gate.follow(0.0, 0.0, drove=False)
    fixes.gate.follow(metres, 0.0)


def test_a_bump_into_a_box_wall_fixes_the_position_across_it() -> None:
    from robot.boxfix import BoxFixConfig
    from robot.headingfix import HeadingFixConfig, WallFixes

    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=(0.0, 0.0, 2.0, 2.0))
    wall = _evidence_with_solid(frame, [(2.02, float(y)) for y in np.arange(0.0, 2.0, 0.05)])
    fixes = WallFixes(frame, ROBOT, BoxFixConfig(), HeadingFixConfig())

    def bump(believed: Pose, direction_deg: float, evidence) -> tuple[Pose, bool, tuple[float, float]]:
        dr = DeadReckoning(ROBOT, believed)
        pose, unexplained = fixes.contact(dr, believed, math.radians(direction_deg), evidence)
        return pose, unexplained, (dr.estimate.x, dr.estimate.y)

    # After 10 m without a fix, the estimate puts the body 10 cm short of the east wall when it
    # touches it: the wall is right.
    _driven(fixes, 10.0)
    pose, unexplained, xy = bump(Pose(2.0 - ROBOT.radius_m - 0.10, 1.0, 0.0), 0.0, wall)
    assert not unexplained and xy == pytest.approx((2.0 - ROBOT.radius_m, 1.0))
    assert (pose.x, pose.y) == pytest.approx(xy)
    # Diagonally into the same wall still counts; driving along it, or far from it, does not.
    _driven(fixes, 10.0)
    assert not bump(Pose(1.85, 1.0, 0.0), -45.0, wall)[1]
    _driven(fixes, 10.0)
    assert bump(Pose(1.85, 1.0, 0.0), 80.0, wall)[1]
    assert bump(Pose(1.5, 1.0, 0.0), 0.0, wall)[1]
    # Where the map does not show the box edge as a wall (a corner of an angled wall may touch
    # it), the bump is something else and is kept as contact evidence.
    before = Pose(2.0 - ROBOT.radius_m - 0.05, 1.0, 0.0)
    pose, unexplained, _ = bump(before, 0.0, _evidence_with_solid(frame, [(2.02, 1.0)]))
    assert unexplained and pose == before


def test_a_bump_where_a_corner_touches_the_box_edge_is_not_a_box_fix() -> None:
    """Where two walls of a room that is not a box meet at a corner on a box edge, the map shows the
    edge solid around the corner (echo arcs smear it) but nowhere else along it: a bump into one of
    those walls, a few centimetres short of the box edge, is not the box wall. Along a box wall,
    a bump near the box's own corner still fixes the position (the check stops at the corner)."""
    from robot.boxfix import BoxFixConfig
    from robot.headingfix import HeadingFixConfig, WallFixes

    grid = GridSpec(0.0, 0.0, 0.2, 15, 15)
    frame = MapFrame(grid=grid, start=Pose(1.5, 1.5, 0.0), extent=(0.0, 0.0, 3.0, 3.0))
    fixes = WallFixes(frame, ROBOT, BoxFixConfig(), HeadingFixConfig())
    rising = np.arange(0.0, 1.2, 0.025)
    corner = [(1.5 - t * math.cos(math.radians(20)), t * math.sin(math.radians(20))) for t in rising]
    corner += [(1.5 + t * math.cos(math.radians(25)), t * math.sin(math.radians(25))) for t in rising]
    corner += [(float(x), -0.01) for x in np.arange(1.35, 1.66, 0.05)]  # the smear at the corner
    believed = Pose(1.55, ROBOT.radius_m + 0.08, 0.0)  # 8 cm short of touching the box edge
    _driven(fixes, 10.0)  # far enough for 8 cm of drift
    dr = DeadReckoning(ROBOT, believed)
    pose, unexplained = fixes.contact(dr, believed, math.radians(-90.0), _evidence_with_solid(frame, corner))
    assert unexplained and pose == believed and (dr.estimate.x, dr.estimate.y) == (believed.x, believed.y)

    # The same bump next to the box's corner, with the bottom wall solid along its whole length.
    along = np.arange(0.0, 3.0, 0.05)
    wall = [(float(x), -0.01) for x in along] + [(-0.01, float(y)) for y in along]
    believed = Pose(0.15, ROBOT.radius_m + 0.08, 0.0)
    dr = DeadReckoning(ROBOT, believed)
    pose, unexplained = fixes.contact(dr, believed, math.radians(-90.0), _evidence_with_solid(frame, wall))
    assert not unexplained and (pose.x, pose.y) == pytest.approx((0.15, ROBOT.radius_m))


def test_a_bump_into_a_wall_that_slants_into_the_box_edge_is_not_a_box_fix() -> None:
    """In a room that is not a rectangle, two walls a few degrees off an axis can meet at a vertex on
    the box edge. Echo arcs smear the vertex along the edge, enough for the check across the body's
    width, but further along the walls run away from the edge: a bump into them is not the box wall
    (a generated polygon ended 17.8 cm off after such a bump moved the estimate by 8.7 cm)."""
    from robot.boxfix import BoxFixConfig
    from robot.headingfix import HeadingFixConfig, WallFixes

    grid = GridSpec(0.0, 0.0, 0.2, 15, 15)
    frame = MapFrame(grid=grid, start=Pose(1.5, 1.5, 0.0), extent=(0.0, 0.0, 3.0, 3.0))
    slant = math.tan(math.radians(6.0))
    along = np.arange(-1.2, 1.2, 0.025)
    solid = [(-0.01, 1.5 + float(t)) for t in along if abs(t) <= 0.4]  # the smear at the vertex
    solid += [(slant * abs(float(t)) - 0.01, 1.5 + float(t)) for t in along]  # the two walls
    evidence = _evidence_with_solid(frame, solid)
    believed = Pose(ROBOT.radius_m + 0.08, 1.5, math.pi)  # 8 cm short of touching the box edge

    def bump(config: BoxFixConfig) -> tuple[Pose, bool]:
        dr = DeadReckoning(ROBOT, believed)
        fixes = WallFixes(frame, ROBOT, config, HeadingFixConfig())
        _driven(fixes, 10.0)  # far enough for 8 cm of drift
        return fixes.contact(dr, believed, math.pi, evidence)

    pose, unexplained = bump(BoxFixConfig())
    assert unexplained and pose == believed
    # Without the check along the edge, the bump passes for the box wall.
    pose, unexplained = bump(BoxFixConfig(along_window_m=0.0))
    assert not unexplained and pose.x == pytest.approx(ROBOT.radius_m)


def test_a_bump_corrects_no_more_drift_than_the_distance_driven_since_the_last_fix_allows() -> None:
    """Just after a fix the estimate is within centimetres across the wall: a bump 10-15 cm short of
    the box edge then is some other wall (near a vertex of a room that is not a rectangle), and
    taking it for the box wall moved the estimate by as much (a generated polygon ended 17 cm off).
    The bound is the sonar fixes' gate (``DriftGate``), which grows with the distance driven."""
    from robot.boxfix import BoxFixConfig
    from robot.headingfix import HeadingFixConfig, WallFixes

    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=(0.0, 0.0, 2.0, 2.0))
    wall = _evidence_with_solid(frame, [(2.02, float(y)) for y in np.arange(0.0, 2.0, 0.05)])
    config = BoxFixConfig()
    fixes = WallFixes(frame, ROBOT, config, HeadingFixConfig())
    short = Pose(2.0 - ROBOT.radius_m - 0.10, 1.0, 0.0)  # 10 cm short of touching the east wall

    def bump(believed: Pose) -> bool:
        return not fixes.contact(DeadReckoning(ROBOT, believed), believed, 0.0, wall)[1]

    assert config.gate_m + config.contact_spare_m < 0.10
    assert not bump(short)  # nothing driven yet
    assert bump(Pose(2.0 - ROBOT.radius_m - config.gate_m, 1.0, 0.0))  # within the fixed gate
    # 10 cm of drift needs (10 - 2 - 5) cm / 2 cm per metre = 1.5 m of driving since that fix.
    _driven(fixes, 1.2)
    assert not bump(short)
    _driven(fixes, 0.4)
    assert bump(short)
    assert not bump(short)  # the bump was a fix: the bound starts again
    # A bound of the contact gate alone takes the first bump.
    fixes = WallFixes(frame, ROBOT, BoxFixConfig(contact_spare_m=1.0), HeadingFixConfig())
    assert bump(short)


def test_heading_fixes_keep_a_large_room_on_the_truth() -> None:
    """In a 7 x 6 m room most of the run is far from any wall: with heading fixes off, the gyro's
    drift leaves the heading over a degree off by the end, and the position drifts with it (on
    seed 0 the 90th percentile of the position error along the run is 6 cm, 2.6 cm with fixes).
    The robot walks every cell, as the paper's does: a long run, over which drift adds up."""
    cfg = load_run_config(None, {"end_when_mapped": False})
    world = load_world("bigroom")
    with_fixes = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    off = cfg.slam.model_copy(update={"heading_fix": cfg.slam.heading_fix.model_copy(update={"enabled": False})})
    without = simulate(world, cfg.robot, cfg.noise, off, seed=0)
    assert with_fixes.final_theta_error_deg < 1.0 < without.final_theta_error_deg
    assert _position_error_p90(with_fixes) < 0.04 < _position_error_p90(without)
    assert with_fixes.metrics.f1 > without.metrics.f1


def _box_fix(frame: MapFrame, robot: RobotConfig, pose: Pose, ranges, config, evidence=None) -> tuple[float, float]:
    """The position shift one sweep's box fixes within the fixed gate make, as ``WallFixes.apply``
    applies it: ``gain`` times the offsets."""
    ox, oy = box_offsets(frame, robot, pose, ranges, config, evidence)
    return (config.gain * ox if ox is not None else 0.0), (config.gain * oy if oy is not None else 0.0)


def _position_error_p90(result: RunResult) -> float:
    """The 90th percentile of the position error [m] over the run's trajectory."""
    t = np.array(result.trajectory)
    return float(np.percentile(np.hypot(t[:, 1] - t[:, 4], t[:, 2] - t[:, 5]), 90))


def _evidence_with_solid(frame: MapFrame, solid_xy: list[tuple[float, float]]):
    from robot.mapping.base import Evidence

    g = frame.grid
    rows, cols = (round((n * g.resolution + 0.6) / 0.05) for n in (g.rows, g.cols))
    fine = GridSpec(g.origin_x - 0.3, g.origin_y - 0.3, 0.05, rows, cols)
    logodds = np.zeros(fine.shape, dtype=np.float32)
    for x, y in solid_xy:
        r, c = fine.world_to_index(x, y)
        logodds[int(r), int(c)] = 5.0
    return Evidence(fine, logodds)


def test_box_fixes_need_the_map_to_show_the_box_edge_as_a_wall() -> None:
    """In a room that is not a rectangle, a corner can touch the box edge at one point: an echo from
    near it must not count until the map shows a wall along the edge across the beam's footprint."""
    from robot.boxfix import BoxFixConfig

    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=(0.0, 0.0, 2.0, 2.0))
    believed = Pose(1.04, 1.0, 0.0)
    ranges = np.full(8, ROBOT.sonar.max_range_m)
    ranges[0] = 2.0 - 1.0 - ROBOT.sonars[0].offset_x_m
    config = BoxFixConfig(gain=1.0)
    ys = np.arange(0.6, 1.4, 0.05)
    wall = _evidence_with_solid(frame, [(2.02, float(y)) for y in ys])  # a wall just past the edge
    corner = _evidence_with_solid(frame, [(2.02, 1.0), (1.95, 0.9), (1.95, 1.1), (1.85, 0.8), (1.85, 1.2)])
    empty = _evidence_with_solid(frame, [])
    assert _box_fix(frame, ROBOT, believed, ranges, config, wall)[0] == pytest.approx(-0.04, abs=1e-9)
    assert _box_fix(frame, ROBOT, believed, ranges, config, corner) == (0.0, 0.0)
    assert _box_fix(frame, ROBOT, believed, ranges, config, empty) == (0.0, 0.0)


def test_box_fixes_ignore_a_wall_that_slants_into_the_box_edge() -> None:
    """In a room that is not a rectangle a wall a few degrees off an axis can meet the box edge at a
    vertex: near there it passes within the gate of the edge, solid across the beam's footprint,
    but over a longer stretch it slants away from the edge, and its echoes must not count."""
    from robot.boxfix import BoxFixConfig

    grid = GridSpec(0.0, 0.0, 0.2, 10, 10)
    frame = MapFrame(grid=grid, start=Pose(1.0, 1.0, 0.0), extent=(0.0, 0.0, 2.0, 2.0))
    ranges = np.full(8, ROBOT.sonar.max_range_m)
    ranges[0] = 2.0 - 0.03 - 1.0 - ROBOT.sonars[0].offset_x_m  # the face 3 cm inside the edge
    believed = Pose(1.0, 1.0, 0.0)
    config = BoxFixConfig(gain=1.0)
    ys = np.arange(0.0, 2.0, 0.025)
    # Solid evidence 2 cm behind each face: a straight wall 3 cm inside the edge, and a wall at 6
    # degrees to it, meeting the edge at y = 1.3.
    along = _evidence_with_solid(frame, [(1.99, float(y)) for y in ys])
    slant = math.tan(math.radians(6.0))
    slanting = _evidence_with_solid(frame, [(2.0 - slant * (1.3 - float(y)) + 0.02, float(y)) for y in ys if y <= 1.3])
    assert _box_fix(frame, ROBOT, believed, ranges, config, along)[0] == pytest.approx(0.03, abs=1e-9)
    assert _box_fix(frame, ROBOT, believed, ranges, config, slanting) == (0.0, 0.0)
    # Without the check along the edge, the slanting wall passes the test across the footprint.
    unchecked = config.model_copy(update={"along_window_m": 0.0})
    assert _box_fix(frame, ROBOT, believed, ranges, unchecked, slanting)[0] == pytest.approx(0.03, abs=1e-9)


def test_the_box_fix_gate_grows_with_the_distance_driven_since_the_last_fix() -> None:
    from robot.boxfix import BoxFixConfig, DriftGate

    gate = DriftGate(BoxFixConfig(gate_m=0.05, gate_growth=0.02, max_gate_m=0.15, gain=0.3))
    gate.follow(0.0, 0.0)
    gate.follow(3.0, 4.0)  # 5 m driven
    assert gate.limit(0) == pytest.approx(0.15) and gate.limit(1) == pytest.approx(0.15)
    gate.follow(9.0, 9.0, drove=False)  # moved by a fix, not driven
    assert gate.travel == pytest.approx([5.0, 5.0])
    gate.fixed(0, 0.07)  # a fix along x leaves 7 cm for later sweeps: the gate stays open for them
    assert gate.limit(0) == pytest.approx(0.09) and gate.limit(1) == pytest.approx(0.15)
    gate.fixed(1, 0.01)
    assert gate.limit(1) == pytest.approx(0.05)
    fixed = DriftGate(BoxFixConfig(gate_growth=0.0))
    fixed.follow(0.0, 0.0)
    fixed.follow(10.0, 0.0)
    assert fixed.limit(0) == pytest.approx(0.05)
    with pytest.raises(ValueError, match="max_gate_m must be at least gate_m"):
        BoxFixConfig(gate_m=0.05, max_gate_m=0.04)


def test_a_drifted_estimate_is_fixed_again_once_readings_along_the_wall_agree() -> None:
    """Once the estimate has drifted past the fixed gate, the fixes stop; the gate grows with the
    distance driven, and a reading past the fixed gate counts once the last few along the wall put
    it at the same offset. An angled wall near the box edge puts it at offsets that change along the
    edge, and never counts."""
    from robot.boxfix import BoxFixConfig
    from robot.headingfix import HeadingFixConfig, WallFixes

    grid = GridSpec(0.0, 0.0, 0.2, 20, 10)  # 2 m east-west, 4 m north-south
    frame = MapFrame(grid=grid, start=Pose(1.5, 0.2, 0.0), extent=(0.0, 0.0, 2.0, 4.0))
    wall = _evidence_with_solid(frame, [(2.02, float(y)) for y in np.arange(0.025, 4.0, 0.05)])
    rng = np.random.default_rng(3)
    repairs: list = []

    def drive(
        config: BoxFixConfig, x: float, face_offset: float, slope: float = 0.0, driven: float = 0.0
    ) -> list[float]:
        """Sweeps every 20 cm (a cell) north along the east wall from the estimate ``x`` (the truth is at
        1.5) after ``driven`` metres without a fix, the face that the echoes show ``face_offset``
        inside the edge at first and ``slope`` m per m closer to it further on: the estimate's x
        after each sweep."""
        fixes = WallFixes(frame, ROBOT, config, HeadingFixConfig(enabled=False))
        fixes.gate.follow(x, 0.1 - driven)
        repairs.clear()
        xs = []
        for y in np.arange(0.1, 4.0, 0.2):
            believed = Pose(x, float(y), 0.0)
            dr = DeadReckoning(ROBOT, believed)
            ranges = np.full(8, ROBOT.sonar.max_range_m)
            face = 2.0 - face_offset + slope * (float(y) - 0.1)
            ranges[0] = face - 1.5 - ROBOT.sonars[0].offset_x_m + rng.normal(0.0, 0.005)
            fixes.apply(dr, believed, ranges, wall)
            repairs.extend(fixes.take_repairs())
            x = dr.estimate.x
            xs.append(x)
        return xs

    # The estimate 8 cm west of the truth: no fix until the gate has grown past 8 cm (1.5 m driven)
    # and six readings agree; then the fix corrects the whole offset at once, and asks for the map
    # to be repaired.
    xs = drive(BoxFixConfig(), 1.42, 0.0)
    first = next(i for i, x in enumerate(xs) if x != 1.42)
    assert 12 <= first <= 15
    assert abs(xs[first] - 1.5) < 0.015 and abs(xs[-1] - 1.5) < 0.015
    assert len(repairs) == 1 and repairs[0].axis == 0 and repairs[0].offset_m == pytest.approx(0.08, abs=0.015)
    # Without the repair, it corrects 30 % of the offset per sweep, as any fix does.
    xs = drive(BoxFixConfig(drift_repair=False), 1.42, 0.0)
    first = next(i for i, x in enumerate(xs) if x != 1.42)
    assert xs[first] - 1.42 == pytest.approx(0.3 * 0.08, abs=0.01) and abs(xs[-1] - 1.5) < 0.015
    assert not repairs
    assert all(x == 1.42 for x in drive(BoxFixConfig(gate_growth=0.0), 1.42, 0.0))  # a fixed gate: never again
    # The estimate right, after 5 m without a fix: an angled wall 14 cm inside the edge, 1 cm closer
    # every 20 cm, puts the wall at offsets that change along the edge, and never counts (until
    # it is within the fixed gate, at y = 1.9) ...
    xs = drive(BoxFixConfig(), 1.5, 0.14, 0.05, driven=5.0)
    assert all(x == 1.5 for x in xs[:9])
    # ... as it would without the test on the readings' line.
    xs = drive(BoxFixConfig(wide_max_slope=1.0, wide_rms_m=1.0), 1.5, 0.14, 0.05, driven=5.0)
    assert any(x != 1.5 for x in xs[:9])


def test_a_fix_past_the_gate_may_rely_on_the_map_from_before_the_drift() -> None:
    """While the estimate drifted, walls were marked where it put them: the map so far shows the east
    wall 8 cm inside the edge too, and refuses readings past the gate. The map as it was at the axis's
    last fix within the gate shows the wall on the edge only, and readings it accepts count. Where
    that map too showed a face inside the edge (a shelf seen before), they do not."""
    from robot.boxfix import BoxFixConfig
    from robot.headingfix import HeadingFixConfig, WallFixes

    grid = GridSpec(0.0, 0.0, 0.2, 20, 10)  # 2 m east-west, 4 m north-south
    frame = MapFrame(grid=grid, start=Pose(1.5, 0.1, 0.0), extent=(0.0, 0.0, 2.0, 4.0))
    ys = np.arange(0.025, 4.0, 0.05)
    wall = _evidence_with_solid(frame, [(2.02, float(y)) for y in ys])
    drifted = _evidence_with_solid(frame, [(2.02, float(y)) for y in ys] + [(1.94, float(y)) for y in ys])

    def drive(first_map) -> list[float]:
        fixes = WallFixes(frame, ROBOT, BoxFixConfig(), HeadingFixConfig(enabled=False))
        x, xs = 1.5, []
        for i, y in enumerate(np.arange(0.1, 4.0, 0.2)):
            believed = Pose(x, float(y), 0.0)
            dr = DeadReckoning(ROBOT, believed)
            ranges = np.full(8, ROBOT.sonar.max_range_m)
            ranges[0] = 2.0 - 1.5 - ROBOT.sonars[0].offset_x_m
            fixes.apply(dr, believed, ranges, first_map if i == 0 else drifted)
            # Right at the first sweep; then 8 cm west of the truth, as after a drift.
            x = dr.estimate.x if i > 0 else 1.42
            xs.append(x)
        return xs

    assert abs(drive(wall)[-1] - 1.5) < 0.01
    assert drive(drifted)[-1] == 1.42


def test_a_wall_seen_beyond_the_box_edge_fixes_a_drift_past_the_gate_that_the_map_cannot_confirm() -> None:
    """No wall of the room lies beyond its box. Readings that put the east wall past the box edge say
    that the estimate has drifted towards the room's inside, whatever the map drawn by that estimate
    shows (the wall where the drift put it, past the edge): they count once the gate has grown and
    the readings along the wall agree, up to ``outside_gate_m``, past the 15 cm that bounds other
    readings. In a 16 x 12 m hall a heading 0.9 degrees off during one 10 m crossing had left the
    estimate 27 cm off for the rest of the run, which no fix could put right (F1 0.49, 41.8 cm off
    at the end; 0.977 and 4.0 cm with this)."""
    from robot.boxfix import BoxFixConfig
    from robot.headingfix import HeadingFixConfig, WallFixes

    grid = GridSpec(0.0, 0.0, 0.2, 20, 10)  # 2 m east-west, 4 m north-south
    frame = MapFrame(grid=grid, start=Pose(1.5, 0.1, 0.0), extent=(0.0, 0.0, 2.0, 4.0))
    ys = np.arange(0.025, 4.0, 0.05)
    rng = np.random.default_rng(4)
    repairs: list = []

    def drive(config: BoxFixConfig, drift: float, driven: float) -> list[float]:
        """Sweeps every 20 cm north along the east wall with the estimate ``drift`` east of the truth
        (at 1.5) after ``driven`` metres without a fix, the map showing the wall where the drifted
        estimate put it: the estimate's x after each sweep."""
        fixes = WallFixes(frame, ROBOT, config, HeadingFixConfig(enabled=False))
        fixes.gate.follow(1.5 + drift, 0.1 - driven)
        drifted = _evidence_with_solid(frame, [(2.02 + drift, float(y)) for y in ys])
        repairs.clear()
        x, xs = 1.5 + drift, []
        for y in np.arange(0.1, 4.0, 0.2):
            believed = Pose(x, float(y), 0.0)
            dr = DeadReckoning(ROBOT, believed)
            ranges = np.full(8, ROBOT.sonar.max_range_m)
            ranges[0] = 2.0 - 1.5 - ROBOT.sonars[0].offset_x_m + rng.normal(0.0, 0.005)
            fixes.apply(dr, believed, ranges, drifted)
            repairs.extend(fixes.take_repairs())
            x = dr.estimate.x
            xs.append(x)
        return xs

    # 10 cm east: fixed once six readings agree (the gate is open after 5 m), the whole offset at once.
    xs = drive(BoxFixConfig(), 0.1, driven=5.0)
    assert abs(xs[-1] - 1.5) < 0.015
    assert len(repairs) == 1 and repairs[0].offset_m == pytest.approx(-0.1, abs=0.015)
    # 27 cm east after 20 m: past the 15 cm of other readings, within the 50 cm of these.
    xs = drive(BoxFixConfig(), 0.27, driven=20.0)
    assert abs(xs[-1] - 1.5) < 0.015 and len(repairs) == 1
    # Not before the gate has grown to the offset (5 cm plus 2 cm a metre driven) ...
    assert drive(BoxFixConfig(), 0.27, driven=5.0)[-1] == pytest.approx(1.77)
    # ... nor past outside_gate_m, nor with the rule off: then the map must show the edge, which the
    # drifted map does not.
    assert drive(BoxFixConfig(outside_gate_m=0.2), 0.27, driven=20.0)[-1] == pytest.approx(1.77)
    assert drive(BoxFixConfig(outside_gate_m=0.0), 0.1, driven=5.0)[-1] == pytest.approx(1.6)
    assert not repairs


def test_a_wall_reached_after_a_drift_away_from_it_fixes_the_drift_where_nothing_was_seen_before() -> None:
    """The robot reaches the east wall for the first time after a long crossing, its estimate already
    8 cm west of the truth, away from the wall: the echoes put the wall 8 cm inside the box edge,
    the map so far shows it there, and the map from the axis's last fix shows nothing there. The
    readings count once eight of them, taken in one pass along the wall over 1.2 m, agree, if the
    heading's doubt over the crossing allows that much drift. A face seen there before the drift (a
    shelf), readings taken back and forth, or a crossing with the heading well known, do not count.
    In a 7.25 x 6.55 m hall the estimate had run 7-13 cm off, away from the bottom wall, for a
    quarter of the run, and the wall was mapped a row in (F1 0.885; 0.982 with this)."""
    from robot.boxfix import BoxFixConfig
    from robot.headingfix import HeadingFixConfig, WallFixes

    grid = GridSpec(0.0, 0.0, 0.2, 20, 10)  # 2 m east-west, 4 m north-south
    frame = MapFrame(grid=grid, start=Pose(1.5, 0.1, 0.0), extent=(0.0, 0.0, 2.0, 4.0))
    near = [(2.02, float(y)) for y in np.arange(0.025, 0.6, 0.05)]  # the wall seen at the first fix
    further = np.arange(0.725, 4.0, 0.05)
    first_map = _evidence_with_solid(frame, near)
    shelf = _evidence_with_solid(frame, near + [(1.94, float(y)) for y in further])
    rng = np.random.default_rng(5)
    repairs: list = []

    def drive(
        config: BoxFixConfig,
        drift: float = 0.08,
        theta_std: float = 0.01,
        face_offset: float = 0.0,
        seen: bool = False,
        first_fix: bool = True,
        ys: list[float] | None = None,
    ) -> float:
        """A first fix at y = 0.1 (unless not ``first_fix``), a 5 m crossing with ``theta_std`` of
        doubt in the heading, then sweeps along the wall at ``ys`` with the estimate ``drift`` west of
        the truth (1.5) and the face ``face_offset`` inside the edge (the map from the first fix
        showing it, when ``seen``): the estimate's x at the end."""
        fixes = WallFixes(frame, ROBOT, config, HeadingFixConfig(enabled=False))
        if first_fix:
            believed = Pose(1.5, 0.1, 0.0)
            ranges = np.full(8, ROBOT.sonar.max_range_m)
            ranges[0] = 2.0 - 1.5 - ROBOT.sonars[0].offset_x_m
            fixes.apply(DeadReckoning(ROBOT, believed), believed, ranges, shelf if seen else first_map)
        for y in (2.6, 0.1):  # out and back: 5 m driven across the x axis
            fixes.gate.follow(1.5, y, theta_std=theta_std)
        wall_x = 2.0 - face_offset
        drawn = _evidence_with_solid(frame, near + [(wall_x + 0.02 - drift, float(y)) for y in further])
        repairs.clear()
        x = 1.5 - drift
        for y in ys if ys is not None else np.arange(0.8, 4.0, 0.2).tolist():
            believed = Pose(x, y, 0.0)
            dr = DeadReckoning(ROBOT, believed)
            ranges = np.full(8, ROBOT.sonar.max_range_m)
            ranges[0] = wall_x - 1.5 - ROBOT.sonars[0].offset_x_m + rng.normal(0.0, 0.003)
            fixes.apply(dr, believed, ranges, drawn)
            repairs.extend(fixes.take_repairs())
            x = dr.estimate.x
        return x

    # Fixed, the whole offset at once, with the map repaired.
    assert abs(drive(BoxFixConfig()) - 1.5) < 0.015
    assert len(repairs) == 1 and repairs[0].axis == 0 and repairs[0].offset_m == pytest.approx(0.08, abs=0.015)
    # Not with the rule off, nor before the axis has had a fix (a room whose walls never lie on the
    # box, such as a polygon's), nor when the heading was known well enough that the estimate cannot
    # have drifted 8 cm (3 sigma of 5 m at 0.002 rad is 3 cm).
    assert drive(BoxFixConfig(inside_fix=False)) == pytest.approx(1.42)
    assert drive(BoxFixConfig(), first_fix=False) == pytest.approx(1.42)
    assert drive(BoxFixConfig(), theta_std=0.002) == pytest.approx(1.42)
    # A shelf 8 cm deep, seen at the first fix: the estimate is right, and stays so.
    assert drive(BoxFixConfig(), drift=0.0, face_offset=0.08, seen=True) == pytest.approx(1.5)
    # ... which it would not, had the shelf not been seen then.
    assert drive(BoxFixConfig(), drift=0.0, face_offset=0.08) != pytest.approx(1.5, abs=0.02)
    # Readings taken back and forth along the wall (a curved wall near the edge reads as flat).
    zigzag = [0.8 + 0.2 * (i // 2) + 0.4 * (i % 2) for i in range(16)]
    assert drive(BoxFixConfig(), ys=zigzag) == pytest.approx(1.42)


def test_a_drift_away_from_a_wall_read_in_one_pass_may_slope_by_the_headings_doubt() -> None:
    """Driving along a wall with the heading off by delta, the estimate drifts across the wall by
    delta per metre: a drift's readings in one pass lie on a line of that slope, not a flat one. A
    slope within ``inside_slope_sigmas`` of the heading's doubt counts; past it, or with the heading
    well known, only ``inside_max_slope`` does. And a pass over seven cells spans 1.2 m between
    estimated positions that the cell centres put a centimetre either side of their places
    (``span_slack_m``). In an 8.4 x 5.3 m hall the estimate ran 8 cm off the east wall, away from
    it, with the heading 1 degree off, and the wall was mapped a column in (F1 0.904; 1.000 with
    these)."""
    from robot.boxfix import BoxFixConfig, DriftGate

    # A pass down the east wall: the robot approaches at y = 1.3 (two readings there), then drives
    # south a cell at a time; the offsets grow by 1.7 cm a metre, the last one 1.1976 m from the first.
    along = [1.3, 1.3, 1.102, 0.903, 0.701, 0.503, 0.302, 0.102]
    offsets = [0.077 + 0.017 * (1.3 - a) for a in along]

    def counts(theta_std_deg: float, **settings: float) -> bool:
        gate = DriftGate(BoxFixConfig(**settings))
        gate.follow(8.1, 1.3, theta_std=math.radians(theta_std_deg))
        return [gate.admits(0, a, o, inside=True) for a, o in zip(along, offsets, strict=True)][-1]

    assert counts(0.65, inside_slope_sigmas=2.0, span_slack_m=0.01)
    assert not counts(0.65, inside_slope_sigmas=0.0, span_slack_m=0.01)  # 1.7 cm a metre > 1 cm
    assert not counts(0.4, inside_slope_sigmas=2.0, span_slack_m=0.01)  # 2 sigma is 1.4 cm a metre
    assert not counts(0.65, inside_slope_sigmas=2.0, span_slack_m=0.0)  # 2.4 mm short of 1.2 m
    # Flat readings count as before, with no doubt in the heading at all.
    offsets = [0.077] * len(along)
    assert counts(0.0, inside_slope_sigmas=2.0, span_slack_m=0.01)


def test_inside_readings_near_where_the_edge_was_last_on_the_box_are_a_wall_leaving_it() -> None:
    """A wall that leans off a box edge from a vertex on it reads on the edge there and a few
    centimetres inside it further along: readings that put the wall inside the edge within
    ``inside_clear_m`` along it of the edge's last reading within the fixed gate are not a drift."""
    from robot.boxfix import BoxFixConfig, DriftGate

    along = [2.1, 2.3, 2.5, 2.7, 2.9, 3.1, 3.3, 3.5, 3.7]  # a pass up the west edge, one pass
    offsets = [-0.065] * len(along)  # flat, as a drift's would be

    def counts(last_on_edge: float | None, **settings: float) -> bool:
        gate = DriftGate(BoxFixConfig(**settings))
        gate.follow(0.3, 1.7, theta_std=math.radians(0.9))
        if last_on_edge is not None:
            assert gate.admits(1, last_on_edge, -0.02)  # within the fixed gate: on the edge
        return [gate.admits(1, a, o, inside=True) for a, o in zip(along, offsets, strict=True)][-1]

    assert not counts(1.7)  # on the edge 0.4 m from the first reading
    assert counts(1.7, inside_clear_m=0.0)
    assert counts(1.3)  # 0.8 m away: as far as these readings go, a drift
    assert counts(None)


def test_a_repair_rebuilds_the_map_at_poses_corrected_in_proportion_to_the_distance_driven() -> None:
    from robot.mapping.journal import JournaledMapper, Repair

    cfg = load_run_config()
    frame = frame_for_world(small_world(), cfg.slam.resolution)
    odometer = [0.0]

    def build():
        return make_mapper("logodds", frame, cfg.robot, cfg.slam)

    journal = JournaledMapper(build, lambda: odometer[0])
    direct = build()
    repair = Repair(axis=1, offset_m=0.06, from_m=1.0, to_m=2.0)  # right at 1 m driven, 6 cm off at 2 m
    assert (repair.shift(0.5), repair.shift(1.5), repair.shift(3.0)) == pytest.approx((0.0, 0.03, 0.06))
    rng = np.random.default_rng(5)
    for i, x in enumerate(np.arange(0.3, 1.8, 0.1)):
        odometer[0] = 0.2 * i
        pose = Pose(float(x), 0.6, 0.3 * i)
        corrected = Pose(pose.x, pose.y + repair.shift(odometer[0]), pose.theta)
        ranges = rng.uniform(0.2, 1.5, len(cfg.robot.sonars))
        journal.integrate(pose, ranges)
        journal.mark_body(pose)
        direct.integrate(corrected, ranges)
        direct.mark_body(corrected)
    journal.mark_contact(pose, 0.0)
    direct.mark_contact(corrected, 0.0)
    assert not np.array_equal(journal.states(), direct.states())
    journal.repair([repair])
    assert journal.repairs == 1
    assert np.array_equal(journal.evidence().logodds, direct.evidence().logodds)
    assert np.array_equal(journal.states(), direct.states())
    # A mapper that keeps no records (an unknown room) cannot be repaired, and nothing to repair is
    # no work.
    bare = JournaledMapper(build, lambda: 0.0, keep=False)
    bare.repair([])
    with pytest.raises(RuntimeError, match="keeps no records"):
        bare.repair([repair])


def test_a_drifted_estimate_and_its_map_are_put_right_in_a_large_hall() -> None:
    """In the 10 x 10 m midhall (seed 4) the heading drifts while the robot crosses open floor, and
    the estimate drifts past the fixes' fixed gate, with walls marked where the drifted estimate put
    them. The growing gate finds it off, and the repair moves the estimate and rebuilds the map
    (without the fixes of walls reached after a drift away from them, ``inside_fix``: F1 0.968 and
    1.9 cm off at the end; without the repair too, 0.826 and 15.9 cm). Before a wall seen beyond the
    box edge counted past the map's checks, the 9 x 7 m hall showed this (seed 2, without open-floor
    clearing), and midhall's seed 4 ended at 0.583."""
    cfg = load_run_config()
    world = load_world("midhall")
    default = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=4)
    assert default.extra["map_repairs"] >= 1 and default.metrics.f1 >= 0.95

    def without(**settings: bool) -> RunResult:
        box = cfg.slam.box_fix.model_copy(update={"inside_fix": False, **settings})
        return simulate(world, cfg.robot, cfg.noise, cfg.slam.model_copy(update={"box_fix": box}), seed=4)

    repaired, kept = without(), without(drift_repair=False)
    assert repaired.extra["map_repairs"] >= 1 and kept.extra["map_repairs"] == 0
    assert repaired.metrics.f1 >= 0.95
    assert repaired.metrics.f1 >= kept.metrics.f1 + 0.05


def test_a_hall_whose_heading_drifted_finds_its_east_wall_on_the_box_edge() -> None:
    """An 8.4 x 5.3 m hall (a generated furnished room, seed 0): the heading drifts a degree while
    the robot works the west half, and the estimate reaches the east wall 8 cm away from it. Its
    readings along the wall slope by the heading error, which the heading's doubt allows
    (``inside_slope_sigmas``), and the fix comes there; without it, the wall was mapped a column in
    for the rest of the run."""
    room = {
        "name": "hall-drift",
        "boundary": [[8.4, 0.0], [8.4, 5.3], [0.0, 5.3], [0.0, 0.0]],
        "start": {"x": 3.25, "y": 1.65, "theta_deg": 48.0},
        "obstacles": [
            {"shape": "polygon", "points": [[3.35, 2.67], [3.11, 2.93], [2.78, 2.81], [2.8, 2.4], [3.21, 2.35]]},
            {"shape": "rect", "center": [5.9, 0.225], "size": [0.8, 0.55], "angle_deg": 0.0},
        ],
    }
    world = world_from_dict(room, "hall-drift.toml")
    cfg = load_run_config()
    fixed = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
    flat = cfg.slam.box_fix.model_copy(update={"inside_slope_sigmas": 0.0})
    drifted = simulate(world, cfg.robot, cfg.noise, cfg.slam.model_copy(update={"box_fix": flat}), seed=0)
    east = fixed.truth[:, -1] == FREE  # the column along the east wall is floor
    assert (fixed.states[east, -1] == FREE).all()
    assert (drifted.states[east, -1] == OCCUPIED).sum() >= 5
    assert fixed.metrics.f1 >= 0.98 and drifted.metrics.f1 < 0.95
    assert fixed.final_xy_error_m < 0.05


def test_an_occupied_cell_between_the_explored_area_and_unknown_space_gets_a_closer_look() -> None:
    grid = GridSpec(0.0, 0.0, 0.2, 5, 5)
    explorer = Explorer(grid, 1, (4, 2))
    states = np.full(grid.shape, FREE, dtype=np.int8)
    states[0, :] = UNKNOWN  # a strip nobody has seen ...
    states[1, :] = OCCUPIED  # ... behind a row of occupied cells
    states[1, 2] = OCCUPIED
    passable = states == FREE
    free_fraction = np.where(states == FREE, 1.0, np.where(states == OCCUPIED, -1.0, 0.0))
    explorer.visited[2:, :] = True
    doubtful = (states == OCCUPIED) & np.roll(states == UNKNOWN, 1, axis=0)
    assert not explorer.frontier(states, passable).any()
    front = explorer.frontier(states, passable, doubtful)
    assert front[1].all() and front.sum() == grid.cols
    action = explorer.decide((2, 2), math.pi / 2, states, passable, free_fraction, doubtful)
    assert action.kind == "inspect" and action.heading_rad is not None
    # Each doubtful cell is looked at up to max_inspections times, then accepted as blocked.
    for _ in range(100):
        if action.kind == "done":
            break
        here = action.target if action.kind == "move" and action.target is not None else (2, 2)
        action = explorer.decide(here, math.pi / 2, states, passable, free_fraction, doubtful)
    assert action.kind == "done"
    assert {cell for cell in explorer.inspections} <= {(1, c) for c in range(grid.cols)}
    assert all(n <= explorer.max_inspections for n in explorer.inspections.values())
    assert {(1, c) for c in range(grid.cols)} <= explorer.given_up
