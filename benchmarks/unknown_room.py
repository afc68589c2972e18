"""Benchmark: how far the estimate drifts when the SLAM side is not told the room's size.

On real hardware in a room nobody surveyed, the map is a bounded grid centred on the start and
there is no room box: no box fixes, no heading fits from them. What holds the estimate then is dead
reckoning and the walls the robot maps itself (``robot.linefix``). This runs simulated worlds that
way, scores the position estimate against the simulator's truth after every step (in the odometry
frame, whose origin is the start) and prints the mean, worst and final error of each run, with and
without those landmark fixes. The map is not scored: the truth is drawn in the world's frame.

    python benchmarks/unknown_room.py [--seeds 1] [--config FILE] [WORLD ...]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
from pathlib import Path

from robot.config import RobotConfig, SimNoise
from robot.engine import SlamEngine
from robot.errors import SonarSlamError
from robot.runner import frame_for_unknown_room
from robot.settings import load_run_config
from robot.sim.simulator import SimRobot
from robot.slam_config import SlamConfig
from robot.world import World, load_world

WORLDS = ("room3", "lshape", "office", "pentagon", "bigroom", "hall", "largehall", "turnedroom")


def errors_of_run(
    world: World, robot: RobotConfig, noise: SimNoise, slam: SlamConfig, seed: int
) -> tuple[list[float], int, str]:
    """The position error after every step [m], the steps and how the run ended."""
    sim = SimRobot(world, robot, noise, seed=seed)
    frame = frame_for_unknown_room(slam.resolution, slam.unknown_room_size_m)
    engine = SlamEngine(sim, robot, slam, frame)
    start = world.start
    c, s = math.cos(-start.theta), math.sin(-start.theta)
    errors = []
    while not engine.done:
        engine.step()
        true, est = sim.true_pose, engine.pose
        dx, dy = true.x - start.x, true.y - start.y
        errors.append(math.hypot(est.x - (c * dx - s * dy), est.y - (s * dx + c * dy)))
    return errors, engine.stats.steps, engine.stats.terminated_by or "unknown"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=1, help="runs per world (seeds 0..N-1), default 1")
    parser.add_argument("--config", type=Path, default=None, help="a settings file, as `sonarslam run --config`")
    parser.add_argument("--size", type=float, default=20.0, help="grid side, centred on the start [m], default 20")
    parser.add_argument("worlds", nargs="*", default=list(WORLDS), help="built-in names or world files")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"argument --seeds: must be at least 1, got {args.seeds}")
    try:
        cfg = load_run_config(args.config, {"unknown_room_size_m": args.size})
        worlds = [load_world(name) for name in args.worlds]
    except SonarSlamError as exc:
        parser.error(str(exc))
    on = cfg.slam
    off = on.model_copy(update={"line_fix": on.line_fix.model_copy(update={"enabled": False})})
    print("position error in a room of unknown size [cm]: mean / worst / final over each run's steps")
    print(f"{'world':<12s} {'seed':>4s}  {'with landmark fixes (steps)':>30s}  {'without (steps)':>30s}")
    means: dict[str, list[float]] = {"with": [], "without": []}
    for world in worlds:
        for seed in range(args.seeds):
            cells = []
            for key, slam in (("with", on), ("without", off)):
                errors, steps, ended = errors_of_run(world, cfg.robot, cfg.noise, slam, seed)
                mean = 100 * statistics.fmean(errors) if errors else 0.0
                means[key].append(mean)
                note = "" if ended == "complete" else f" ({ended})"
                worst, final = 100 * max(errors, default=0.0), 100 * errors[-1] if errors else 0.0
                cells.append(f"{mean:5.1f} / {worst:5.1f} / {final:5.1f} ({steps}){note}")
            print(f"{world.name:<12s} {seed:4d}  {cells[0]:>30s}  {cells[1]:>30s}", flush=True)
    print(
        f"mean of the runs' mean error: {statistics.fmean(means['with']):.1f} cm with landmark fixes, "
        f"{statistics.fmean(means['without']):.1f} cm without"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
