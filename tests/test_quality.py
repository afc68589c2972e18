"""Whole simulated runs on every built-in world, default noise: the map and the pose must stay good.

These are regression bars, set below what the worlds measure over several seeds (README), on one
seed each: a change that breaks mapping, exploration or localisation in any kind of room fails here.
"""

from __future__ import annotations

import pytest

from robot.runner import simulate
from robot.settings import load_run_config
from robot.world import load_world

# world: (minimum F1, minimum recall); the large hall is the hardest (few walls in sonar range).
BARS = {
    "room1": (0.93, 0.99),
    "room2": (0.88, 0.90),
    "room3": (0.93, 0.95),
    "room4": (0.93, 0.97),
    "lshape": (0.95, 0.95),
    "corridor": (0.97, 0.97),
    "clutter": (0.88, 0.85),
    "hexagon": (0.93, 0.90),
    "tworooms": (0.90, 0.95),
    "hall": (0.75, 0.90),
}
# Final position error [m]: the 10 cm target everywhere but in the hall, where a run lasts 90
# minutes, mostly out of reach of the box fix's 1.2 m, and the gyro's angle random walk alone adds
# 1-2 degrees of heading error by the end. The hall does not meet the target (README: 9.7 cm mean,
# 23.8 cm worst over 6 seeds, seed 0 among the worst); its bar only catches a collapse.
MAX_XY_ERROR_M = {"hall": 0.30}


@pytest.mark.parametrize("name", sorted(BARS))
def test_a_default_run_maps_the_world_well(name: str) -> None:
    cfg = load_run_config()
    result = simulate(load_world(name), cfg.robot, cfg.noise, cfg.slam, seed=0)
    min_f1, min_recall = BARS[name]
    m = result.metrics
    assert result.terminated_by == "complete"
    assert m.f1 >= min_f1, f"{name}: F1 {m.f1:.3f}"
    assert m.recall >= min_recall, f"{name}: recall {m.recall:.3f}"
    max_xy = MAX_XY_ERROR_M.get(name, 0.10)
    assert result.final_xy_error_m <= max_xy, f"{name}: final position error {result.final_xy_error_m:.3f} m"
    assert result.final_theta_error_deg <= 3.0, f"{name}: final heading error {result.final_theta_error_deg:.2f} deg"
