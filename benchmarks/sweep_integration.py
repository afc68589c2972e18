"""Benchmark: time to integrate one 8-sonar sweep into a 20 x 20 m map at 0.05 m with the default
mapper, over a few hundred random poses and readings; also the time to read the map back (the
engine reads it after every step)."""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

from robot.grid import GridSpec
from robot.mapping import make_mapper
from robot.mapping.base import MapFrame
from robot.settings import load_run_config
from robot.world import Pose

SIZE_M = 20.0  # map side [m]
RESOLUTION_M = 0.05  # map cell side [m]
NO_ECHO_SHARE = 0.3  # share of readings that come back as "no echo"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sweeps", type=int, default=300, help="timed sweeps, default 300")
    parser.add_argument("--mapper", choices=("logodds", "paper"), default=None, help="default: the configured one")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    cfg = load_run_config(None, {"resolution": RESOLUTION_M, "mapper": args.mapper})
    robot, slam = cfg.robot, cfg.slam
    n = round(SIZE_M / RESOLUTION_M)
    grid = GridSpec(0.0, 0.0, RESOLUTION_M, n, n)
    frame = MapFrame(grid=grid, start=Pose(SIZE_M / 2, SIZE_M / 2, 0.0), extent=(0.0, 0.0, SIZE_M, SIZE_M))
    mapper = make_mapper(slam.mapper, frame, robot, slam)
    rng = np.random.default_rng(args.seed)
    lo, hi = robot.sonar.min_range_m, robot.sonar.max_range_m
    n_sonars = len(robot.sonars)

    def random_sweep() -> tuple[Pose, np.ndarray]:
        x, y = rng.uniform(1.0, SIZE_M - 1.0, 2)
        ranges = rng.uniform(lo, hi, n_sonars)
        ranges[rng.random(n_sonars) < NO_ECHO_SHARE] = hi
        return Pose(float(x), float(y), float(rng.uniform(-math.pi, math.pi))), ranges

    for _ in range(10):  # warm-up: first-touch allocations, caches
        mapper.integrate(*random_sweep())
    integrate_ms, read_ms = [], []
    for _ in range(args.sweeps):
        pose, ranges = random_sweep()
        t0 = time.perf_counter()
        mapper.integrate(pose, ranges)
        t1 = time.perf_counter()
        mapper.states()
        t2 = time.perf_counter()
        integrate_ms.append((t1 - t0) * 1000.0)
        read_ms.append((t2 - t1) * 1000.0)

    def describe(values: list[float]) -> str:
        q = statistics.quantiles(values, n=10)
        return f"median {statistics.median(values):7.2f} ms  p10 {q[0]:7.2f}  p90 {q[-1]:7.2f}  max {max(values):7.2f}"

    print(
        f"{slam.mapper} mapper, {SIZE_M:.0f} x {SIZE_M:.0f} m at {RESOLUTION_M} m ({n} x {n} cells), "
        f"{n_sonars} sonars, beam {robot.sonar.beam_width_deg} deg, ranges {lo}-{hi} m, {args.sweeps} sweeps"
    )
    print(f"integrate one sweep:  {describe(integrate_ms)}")
    print(f"read the map back:    {describe(read_ms)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
