"""benchmarks/unknown_room.py: runs a world without telling the SLAM side its size, and scores the
pose against the simulator's truth in the odometry frame."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "unknown_room.py"
_SPEC = importlib.util.spec_from_file_location("unknown_room", _PATH)
assert _SPEC is not None and _SPEC.loader is not None
unknown_room = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(unknown_room)

CLOSET = str(Path(__file__).parent / "data" / "worlds" / "closet.toml")


def test_a_room_of_unknown_size_is_explored_and_its_pose_error_reported(capsys: pytest.CaptureFixture[str]) -> None:
    from robot.settings import load_run_config
    from robot.world import load_world

    cfg = load_run_config()
    errors, steps, ended = unknown_room.errors_of_run(load_world(CLOSET), cfg.robot, cfg.noise, cfg.slam, 0)
    assert ended == "complete" and steps == len(errors) > 10
    assert max(errors) < 0.05  # a closet: centimetres of drift at most

    assert unknown_room.main(["--seeds", "1", CLOSET]) == 0
    out = capsys.readouterr().out
    assert "closet" in out and "mean of the runs' mean error" in out


def test_bad_arguments_are_one_line_errors(capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (["nosuchworld"], ["--seeds", "0"], ["--size", "0.1"]):
        with pytest.raises(SystemExit) as exc:
            unknown_room.main(argv)
        assert exc.value.code == 2
        assert "Traceback" not in capsys.readouterr().err
