"""Benchmark: wall time of a whole simulated run of each of the paper's rooms, and how much faster
than real time the SLAM loop runs (simulated seconds per wall-clock second)."""

from __future__ import annotations

import argparse
import statistics

from robot.runner import simulate
from robot.settings import load_run_config
from robot.world import load_world

ROOMS = ("room1", "room2", "room3", "room4")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=3, help="runs per room (seeds 0..N-1), default 3")
    parser.add_argument("--resolution", type=float, default=0.2, help="map cell side [m], default 0.2")
    parser.add_argument("--mapper", choices=("logodds", "paper"), default=None)
    parser.add_argument("--walk", action="store_true", help="walk every cell, as the paper's robot does")
    parser.add_argument("rooms", nargs="*", default=list(ROOMS))
    args = parser.parse_args(argv)
    overrides = {"resolution": args.resolution, "mapper": args.mapper, "end_when_mapped": not args.walk}
    cfg = load_run_config(None, overrides)
    ending = "walking every cell" if args.walk else "ending when mapped"
    print(f"whole runs at {args.resolution} m, {cfg.slam.mapper} mapper, {ending}, median of {args.seeds} seed(s)")
    heads = ("wall s", "min", "max", "sim s", "sim/wall", "steps", "ms/step")
    print(f"{'world':<8s} " + " ".join(f"{h:>8s}" for h in heads))
    for name in args.rooms:
        world = load_world(name)
        walls, sims, steps = [], [], []
        for seed in range(args.seeds):
            result = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=seed)
            walls.append(result.wall_time_s)
            sims.append(result.sim_time_s)
            steps.append(result.steps)
        wall = statistics.median(walls)
        sim = statistics.median(sims)
        per_step = 1000.0 * sum(walls) / max(sum(steps), 1)
        print(
            f"{name:<8s} {wall:8.2f} {min(walls):8.2f} {max(walls):8.2f} {sim:8.0f} {sim / wall:8.0f} "
            f"{statistics.median(steps):8.0f} {per_step:8.1f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
