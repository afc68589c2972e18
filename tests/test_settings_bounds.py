"""Every numeric setting at the ends of its allowed range, of the run (``[slam]`` and its tables) and
of the robot (``[robot]``, ``[sonar]``, ``[imu]``, ``[sim_noise]``), either is refused with a clear
error or runs: a value the config accepts must never end a run in a traceback, a hang or gigabytes of
memory."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from annotated_types import Ge, Gt, Le, Lt
from pydantic import BaseModel

from robot.config import RobotConfig, SimNoise, SonarModel
from robot.errors import ConfigError, SonarSlamError
from robot.runner import simulate
from robot.settings import load_run_config
from robot.slam_config import SlamConfig
from robot.world import world_from_dict

# Bounds the run itself cannot exercise: the map's resolution has its own tests, and the time caps
# end a run as soon as they pass.
SKIP = {("resolution",), ("time_limit_s",), ("max_sim_time_s",), ("max_steps",)}  # of [slam]


def _ends(model: type[BaseModel], prefix: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], float]]:
    """(path, value) for each end of each bounded int or float field, just inside an open bound."""
    for name, field in model.model_fields.items():
        kind = field.annotation
        path = (*prefix, name)
        if isinstance(kind, type) and issubclass(kind, BaseModel):
            yield from _ends(kind, path)
            continue
        if kind not in (int, float) or path in SKIP:
            continue
        step = 1 if kind is int else 1e-6
        for bound in field.metadata:
            if isinstance(bound, Ge):
                yield path, bound.ge
            elif isinstance(bound, Gt):
                yield path, bound.gt + step
            elif isinstance(bound, Le):
                yield path, bound.le
            elif isinstance(bound, Lt):
                yield path, bound.lt - step


ENDS = [(("slam", *path), value) for path, value in _ends(SlamConfig)]
ROBOT_TABLES: dict[str, type[BaseModel]] = {
    "robot": RobotConfig,
    "sonar": SonarModel,
    "imu": type(RobotConfig().imu),
    "sim_noise": SimNoise,
}
for _table, _model in ROBOT_TABLES.items():
    # [robot] nests [sonar] and [imu], which are swept as tables of their own.
    ENDS += [((_table, *path), value) for path, value in _ends(_model) if len(path) == 1]

WORLD = world_from_dict(
    {
        "name": "bounds",
        "boundary": [[0.0, 0.0], [2.4, 0.0], [2.4, 1.8], [0.0, 1.8]],
        "start": {"x": 0.5, "y": 0.5, "theta_deg": 90.0},
        "obstacles": [{"shape": "rect", "center": [1.5, 1.0], "size": [0.4, 0.3], "angle_deg": 20.0}],
    },
    "bounds.toml",
)


def test_the_sweep_covers_every_table() -> None:
    tables = {".".join(path[:2]) for path, _ in ENDS if len(path) > 2}
    assert {"slam.logodds", "slam.motion", "slam.localization", "slam.box_fix", "slam.heading_fix"} <= tables
    assert set(ROBOT_TABLES) <= {path[0] for path, _ in ENDS}
    assert len(ENDS) > 160


@pytest.mark.parametrize(("path", "value"), ENDS, ids=[f"{'.'.join(p)}={v:g}" for p, v in ENDS])
def test_a_setting_at_the_end_of_its_range_is_refused_or_runs(
    tmp_path: Path, path: tuple[str, ...], value: Any
) -> None:
    table = ".".join(path[:-1])
    text = "[slam]\nmax_steps = 12\n" + (f"[{table}]\n" if table != "slam" else "") + f"{path[-1]} = {value!r}\n"
    config = tmp_path / "bounds.toml"
    config.write_text(text)
    try:
        cfg = load_run_config(config, {})
    except ConfigError as exc:
        assert "\n" not in str(exc) and "bounds.toml" in str(exc)
        return
    try:
        result = simulate(WORLD, cfg.robot, cfg.noise, cfg.slam, seed=0)
    except SonarSlamError as exc:  # a robot too large for the room's start, say: a clear error
        assert "\n" not in str(exc)
        return
    assert result.terminated_by in {"complete", "time_limit", "safety_cap", "boxed_in"}
    assert result.steps <= 12
