"""Whole simulated runs on every built-in world, default noise: the map and the pose must stay good.

These are regression bars, set below what the worlds measure over several seeds (README), on one
seed each: a change that breaks mapping, exploration or localisation in any kind of room fails here.
"""

from __future__ import annotations

import pytest

from robot.runner import simulate
from robot.settings import load_run_config
from robot.world import load_world

# world: (minimum F1, minimum recall).
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
    "hall": (0.90, 0.90),
    "bigroom": (0.93, 0.92),
    "longroom": (0.90, 0.85),
    "trapezoid": (0.93, 0.92),
    "ushape": (0.94, 0.97),
    "office": (0.95, 0.96),
    "ring": (0.94, 0.97),
    "lhall": (0.94, 0.97),
    "cornered": (0.93, 0.90),
    "openhall": (0.93, 0.95),
    "pentagon": (0.94, 0.92),
    "heptagon": (0.93, 0.90),
    "roundroom": (0.86, 0.78),
    "turnedroom": (0.95, 0.93),
    "midhall": (0.88, 0.88),
    # Added on 2026-12-06. The pillars' bar is low: with 8 black cells in the truth, each grey cell
    # beside a pillar costs about 0.06 of F1 (README, "Our own worlds").
    "pillars": (0.75, 0.95),
    "zigzag": (0.97, 0.98),
    "passage": (0.93, 0.97),
    "livingroom": (0.95, 0.95),
    "diamond": (0.97, 0.97),
    # Added on 2026-12-07: a 16 x 12 m hall, where seed 0 drifts 27 cm during one crossing.
    "largehall": (0.93, 0.93),
}
# The large rooms may also end by the time limit, the paper's other rule: on the hall's seed 0
# four frontier cells stayed while the robot visited the cells it had left, and the map did not
# change for 20 minutes.
ENDS = {name: ("complete", "time_limit") for name in ("hall", "lhall", "openhall", "midhall", "largehall")}


@pytest.mark.parametrize("name", sorted(BARS))
def test_a_default_run_maps_the_world_well(name: str) -> None:
    cfg = load_run_config()
    result = simulate(load_world(name), cfg.robot, cfg.noise, cfg.slam, seed=0)
    min_f1, min_recall = BARS[name]
    m = result.metrics
    assert result.terminated_by in ENDS.get(name, ("complete",))
    assert m.f1 >= min_f1, f"{name}: F1 {m.f1:.3f}"
    assert m.recall >= min_recall, f"{name}: recall {m.recall:.3f}"
    assert result.final_xy_error_m <= 0.10, f"{name}: final position error {result.final_xy_error_m:.3f} m"
    assert result.final_theta_error_deg <= 3.0, f"{name}: final heading error {result.final_theta_error_deg:.2f} deg"
