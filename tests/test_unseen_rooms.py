"""The room generator of benchmarks/unseen_rooms.py: valid worlds, reproducible, and their files load."""

from __future__ import annotations

import importlib.util
import random
from pathlib import Path

from robot.world import load_world_text, world_from_dict

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "unseen_rooms.py"
_SPEC = importlib.util.spec_from_file_location("unseen_rooms", _PATH)
assert _SPEC is not None and _SPEC.loader is not None
unseen_rooms = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(unseen_rooms)


def _rooms(seed: int, count: int, style: str = "mixed") -> list[dict]:
    rng = random.Random(seed)
    out: list[dict] = []
    while len(out) < count:
        data = unseen_rooms.random_world(rng, f"r{len(out)}", style)
        if data is not None:
            out.append(data)
    return out


def test_generated_rooms_are_valid_worlds_whose_files_load_the_same() -> None:
    rooms = _rooms(3, 12)
    kinds = {data["description"] for data in rooms}
    assert any(k.endswith("polygon") for k in kinds) and len(kinds) >= 3
    for data in rooms:
        world = world_from_dict(data, "generated.toml")
        again = load_world_text(unseen_rooms.to_toml(data), "generated.toml")
        assert again.boundary.equals(world.boundary)
        assert len(again.obstacles) == len(world.obstacles)
        assert (again.start.x, again.start.y, again.start.theta) == (world.start.x, world.start.y, world.start.theta)


def test_furnished_rooms_hold_every_shape_furniture_by_the_walls_and_any_start_heading() -> None:
    rooms = _rooms(4, 16, "furnished")
    shapes = {o["shape"] for data in rooms for o in data["obstacles"]}
    assert shapes == {"rect", "circle", "ellipse", "polygon"}
    headings = {data["start"]["theta_deg"] for data in rooms}
    assert any(h % 90 != 0 for h in headings)
    by_a_wall = pulled_out = 0
    for data in rooms:
        world = world_from_dict(data, "furnished.toml")
        again = load_world_text(unseen_rooms.to_toml(data), "furnished.toml")
        assert again.boundary.equals(world.boundary) and len(again.obstacles) == len(world.obstacles)
        min_x, min_y, max_x, max_y = world.boundary.bounds
        for obstacle in world.obstacles:
            if obstacle.shape != "rect":
                continue
            x0, y0, x1, y1 = obstacle.polygon.bounds
            gaps = (x0 - min_x, y0 - min_y, max_x - x1, max_y - y1)
            by_a_wall += min(gaps) < 0
            pulled_out += any(0.09 < g < 0.31 for g in gaps)
    # Wardrobes flush with a wall, and furniture pulled out of one: a slot about the robot's width.
    assert by_a_wall >= 3 and pulled_out >= 3


def test_the_same_seed_gives_the_same_rooms() -> None:
    assert _rooms(5, 4) == _rooms(5, 4)
    assert _rooms(5, 4) != _rooms(6, 4)
    assert _rooms(5, 4, "furnished") == _rooms(5, 4, "furnished") != _rooms(5, 4)


def test_a_bad_settings_file_is_refused_in_one_line(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("[slam.box_fix]\nenabled = 3\n")
    for path in (bad, tmp_path / "missing.toml"):
        try:
            unseen_rooms.main(["--rooms", "1", "--config", str(path)])
        except SystemExit as exc:
            assert exc.code == 2
        else:
            raise AssertionError("a bad settings file ran")
        err = capsys.readouterr().err.strip().splitlines()
        assert str(path) in err[-1] and "Traceback" not in "\n".join(err)
