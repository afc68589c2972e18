"""The simulator's physics: odometry, collisions, sonar geometry and the ultrasound error model."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from robot.config import RobotConfig, SimNoise, SonarModel
from robot.errors import WorldError
from robot.sim import SimRobot
from robot.sim.sonar import cone_candidates, simulate_ranges
from robot.world import world_from_dict

ROBOT = RobotConfig()


def box_world(
    width: float = 6.0, height: float = 4.0, x: float = 1.0, y: float = 2.0, theta_deg: float = 0.0, obstacles=()
):
    return world_from_dict(
        {
            "name": "box",
            "boundary": [[0.0, 0.0], [width, 0.0], [width, height], [0.0, height]],
            "start": {"x": x, "y": y, "theta_deg": theta_deg},
            "obstacles": list(obstacles),
        },
        "box.toml",
    )


def test_encoder_distance_matches_true_distance_within_quantisation() -> None:
    sim = SimRobot(box_world(), ROBOT, SimNoise.off(), seed=3)
    sim.set_wheel_speeds(0.2, 0.2)
    sim.sleep(7.3)
    sim.stop()
    counts = sim.read_encoders()
    travelled = sim.true_pose.x - 1.0
    per_count = ROBOT.metres_per_count
    assert counts.left == counts.right
    assert travelled == pytest.approx(0.2 * 7.3, abs=1e-9)
    assert abs(counts.left * per_count - travelled) < per_count
    assert sim.odometer_m == pytest.approx(travelled)


def test_turning_in_place_changes_heading_not_position() -> None:
    sim = SimRobot(box_world(), ROBOT, SimNoise.off())
    sim.set_wheel_speeds(-0.1, 0.1)
    sim.sleep(1.0)
    pose = sim.true_pose
    assert (pose.x, pose.y) == pytest.approx((1.0, 2.0))
    assert pose.theta == pytest.approx(0.2 / ROBOT.wheel_base_m)
    gyro = np.array([s.gyro_z_rad_s for s in sim.read_imu()])
    assert len(gyro) == 100
    assert gyro.mean() == pytest.approx(0.2 / ROBOT.wheel_base_m)


def test_wheel_radius_mismatch_makes_encoders_disagree_with_ground() -> None:
    noise = SimNoise.off().model_copy(update={"wheel_radius_error_left": 0.05, "wheel_radius_error_right": 0.05})
    sim = SimRobot(box_world(), ROBOT, noise)
    sim.set_wheel_speeds(0.2, 0.2)
    sim.sleep(5.0)
    encoder_m = sim.read_encoders().left * ROBOT.metres_per_count
    assert sim.true_pose.x - 1.0 == pytest.approx(1.05 * 1.0, abs=1e-9)
    assert encoder_m == pytest.approx(1.0, abs=ROBOT.metres_per_count)


def test_collision_stops_the_robot_at_the_wall() -> None:
    sim = SimRobot(box_world(x=5.0), ROBOT, SimNoise.off())
    sim.set_wheel_speeds(0.25, 0.25)
    sim.sleep(10.0)
    pose = sim.true_pose
    assert pose.x <= 6.0 - ROBOT.radius_m
    assert pose.x > 6.0 - ROBOT.radius_m - 0.01
    assert sim.collisions > 0
    before = sim.read_encoders().left
    sim.sleep(1.0)  # pushing on: the body and the stalled wheels do not move
    assert sim.true_pose.x == pose.x
    assert sim.read_encoders().left == before


def test_a_body_against_a_wall_still_turns_on_the_spot() -> None:
    # Unequal wheels nudge the centre while turning on the spot; against a wall that nudge must not
    # wedge the robot for good (it did: every turn stalled, and exploration ended early).
    noise = SimNoise.off().model_copy(update={"wheel_radius_error_left": 0.004, "wheel_radius_error_right": -0.004})
    sim = SimRobot(box_world(x=6.0 - ROBOT.radius_m), ROBOT, noise)  # touching the wall at x = 6
    pressed = sim.true_pose
    collisions = sim.collisions
    for sign in (-1.0, 1.0):  # turning clockwise first nudges the centre into the wall
        before = sim.true_pose.theta
        sim.set_wheel_speeds(-0.05 * sign, 0.05 * sign)
        sim.sleep(2.0)
        turned = math.remainder(sim.true_pose.theta - before, 2 * math.pi)
        assert turned == pytest.approx(sign * 2.0 * 0.05 * 2.0 / ROBOT.wheel_base_m, rel=0.02)
    assert sim.true_pose.x <= 6.0 - ROBOT.radius_m + 1e-12
    assert sim.true_pose.x == pytest.approx(pressed.x, abs=1e-3)
    assert sim.collisions >= collisions
    sim.set_wheel_speeds(0.25, 0.25)  # driving on into the wall still stalls
    sim.sleep(1.0)
    assert sim.true_pose.x <= 6.0 - ROBOT.radius_m + 1e-12


def test_a_start_that_leaves_the_body_in_a_wall_is_refused() -> None:
    with pytest.raises(WorldError, match=r"needs 6\.4 cm"):
        SimRobot(box_world(x=0.03), ROBOT, SimNoise.off())
    SimRobot(box_world(x=ROBOT.radius_m), ROBOT, SimNoise.off())  # touching is fine


def test_collision_with_an_obstacle() -> None:
    world = box_world(obstacles=[{"shape": "circle", "center": [2.0, 2.0], "radius": 0.2}])
    sim = SimRobot(world, ROBOT, SimNoise.off())
    sim.set_wheel_speeds(0.25, 0.25)
    sim.sleep(10.0)
    assert sim.true_pose.x == pytest.approx(2.0 - 0.2 - ROBOT.radius_m, abs=0.01)


def test_noiseless_sonar_reads_exact_distances() -> None:
    sim = SimRobot(box_world(x=1.0, y=2.0), ROBOT, SimNoise.off())
    ranges = sim.read_sonar_sweep().ranges_m
    r = ROBOT.radius_m
    assert ranges[0] == pytest.approx(min(5.0 - r, ROBOT.sonar.max_range_m))  # forward: wall at x=6
    assert ranges[2] == pytest.approx(2.0 - r)  # left: wall at y=4
    assert ranges[4] == pytest.approx(1.0 - r)  # behind: wall at x=0
    assert ranges[6] == pytest.approx(2.0 - r)  # right: wall at y=0


def test_sonar_cone_sees_a_thin_pole_off_axis() -> None:
    # A 1 cm pole 12 degrees off the beam axis at 2 m: a single ray would miss it, the cone must not.
    pole = {
        "shape": "circle",
        "center": [1.0 + 2.0 * math.cos(math.radians(12)), 2.0 + 2.0 * math.sin(math.radians(12))],
        "radius": 0.005,
    }
    sim = SimRobot(box_world(obstacles=[pole]), ROBOT, SimNoise.off())
    front = sim.read_sonar_sweep().ranges_m[0]
    assert front == pytest.approx(2.0 - 0.005 - ROBOT.radius_m, abs=0.01)


def test_normal_incidence_reading_is_within_the_noise() -> None:
    noise = SimNoise(false_echo_prob=0.0, dropout_prob=0.0)
    sim = SimRobot(box_world(x=4.0), ROBOT, noise, seed=7)
    readings = np.array([sim.read_sonar_sweep().ranges_m[0] for _ in range(400)])
    expected = 2.0 - ROBOT.radius_m
    sigma = noise.range_noise_m + noise.range_noise_frac * expected
    assert abs(np.median(readings) - expected) < 0.01
    assert np.all(np.abs(readings - expected) < 5 * sigma + noise.range_quantum_m)
    assert readings.std() == pytest.approx(sigma, rel=0.25)


@pytest.mark.parametrize("miss_prob", [0.3, 0.85])
def test_glancing_incidence_misses_at_the_configured_rate(miss_prob: float) -> None:
    # One wall at 60 degrees incidence and nothing else in range.
    noise = SimNoise(specular_miss_prob=miss_prob, false_echo_prob=0.0, dropout_prob=0.0)
    model = SonarModel(max_range_m=4.0)
    inc = math.radians(60.0)
    # Wall through (2, 0) whose normal is 60 degrees from the beam axis (+x), free side towards the origin.
    nx, ny = -math.cos(inc), -math.sin(inc)
    tx, ty = -ny, nx
    seg = np.array([[2.0 - 3 * tx, 0.0 - 3 * ty, 2.0 + 3 * tx, 0.0 + 3 * ty]])
    if (seg[0, 2] - seg[0, 0]) * (-seg[0, 1]) - (seg[0, 3] - seg[0, 1]) * (-seg[0, 0]) < 0:
        seg = seg[:, [2, 3, 0, 1]]
    dist, incidence, _ = cone_candidates(seg, np.zeros((1, 2)), np.zeros(1), math.radians(15.0))
    assert np.isfinite(dist[0, 0])
    assert math.degrees(incidence[0, 0]) >= 45.0
    rng = np.random.default_rng(11)
    readings = np.array([simulate_ranges(dist, incidence, model, noise, rng)[0] for _ in range(4000)])
    missed = np.mean(readings >= model.max_range_m)
    assert missed == pytest.approx(miss_prob, abs=0.03)


def test_normal_incidence_never_misses_specularly() -> None:
    noise = SimNoise(false_echo_prob=0.0, dropout_prob=0.0)
    sim = SimRobot(box_world(x=4.0), ROBOT, noise, seed=2)
    readings = np.array([sim.read_sonar_sweep().ranges_m[0] for _ in range(300)])
    assert np.all(readings < ROBOT.sonar.max_range_m)


def test_dropouts_and_false_echoes_happen_at_their_rates() -> None:
    noise = SimNoise(specular_miss_prob=0.0, false_echo_prob=0.1, dropout_prob=0.1)
    sim = SimRobot(box_world(x=4.0), ROBOT, noise, seed=5)
    readings = np.array([sim.read_sonar_sweep().ranges_m[0] for _ in range(2000)])
    expected = 2.0 - ROBOT.radius_m
    assert np.mean(readings >= ROBOT.sonar.max_range_m) == pytest.approx(0.1, abs=0.02)
    assert np.mean(readings < expected - 0.1) == pytest.approx(0.1 * 0.9, abs=0.025)


def test_gyro_reports_bias_and_noise_when_still() -> None:
    noise = SimNoise(gyro_bias_rad_s=0.02, gyro_noise_std_rad_s=0.003, gyro_bias_walk_rad_s2=0.0)
    sim = SimRobot(box_world(), ROBOT, noise, seed=1)
    sim.sleep(20.0)
    gyro = np.array([s.gyro_z_rad_s for s in sim.read_imu()])
    assert len(gyro) == 2000
    assert gyro.mean() == pytest.approx(0.02, abs=0.0005)
    assert gyro.std() == pytest.approx(0.003, rel=0.1)
    assert sim.read_imu() == []


def test_same_seed_same_run() -> None:
    def run(seed: int) -> list[float]:
        sim = SimRobot(box_world(), ROBOT, SimNoise(), seed=seed)
        sim.set_wheel_speeds(0.2, 0.15)
        sim.sleep(3.0)
        return [*sim.read_sonar_sweep().ranges_m, sim.true_pose.x, sim.true_pose.y]

    assert run(4) == run(4)
    assert run(4) != run(5)


def test_a_slow_sleep_ends_soon_after_the_speed_goes_to_max() -> None:
    # At 0.01 x real time this 3 s sleep would last 5 minutes; a stop sets the speed to None.
    sim = SimRobot(box_world(), ROBOT, SimNoise(), seed=1, speed=0.01)
    done = threading.Event()
    sleeper = threading.Thread(target=lambda: (sim.sleep(3.0), done.set()), daemon=True)
    sleeper.start()
    assert not done.wait(0.2)  # it is pacing
    sim.set_speed(None)
    assert done.wait(10.0)
    assert sim.now() == pytest.approx(3.0)  # the sim time it was asked for, all of it


def test_a_lost_echo_never_lets_a_surface_behind_an_obstacle_answer() -> None:
    # A wall crosses the beam at a glancing angle about 0.8 m ahead, with the far wall 3.4 m away. When the
    # wall's echo is lost, the far wall must not answer through it.
    noise = SimNoise(
        specular_miss_prob=1.0,
        false_echo_prob=0.0,
        dropout_prob=0.0,
        range_noise_m=0.0,
        range_noise_frac=0.0,
        range_quantum_m=0.0,
    )
    block = {"shape": "rect", "center": [2.5, 2.0], "size": [0.2, 3.0], "angle_deg": 65.0}
    sim = SimRobot(box_world(width=4.5, x=1.0, y=2.0, obstacles=[block]), ROBOT, noise, seed=1)
    readings = np.array([sim.read_sonar_sweep().ranges_m[0] for _ in range(50)])
    assert np.all(readings >= ROBOT.sonar.max_range_m)


def test_ray_blocked_sees_segments_between_the_ends() -> None:
    from robot.sim.sonar import ray_blocked

    segs = np.array([[1.0, -1.0, 1.0, 1.0], [3.0, -1.0, 3.0, 1.0]])
    assert ray_blocked(segs, 0.0, 0.0, 2.0, 0.0, skip=-1)
    assert not ray_blocked(segs, 0.0, 0.0, 0.5, 0.0, skip=-1)
    assert not ray_blocked(segs, 0.0, 0.0, 1.0, 0.0, skip=0)
