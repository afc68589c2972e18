"""World files (SPEC §1): good worlds load; every bad one is a WorldError naming the file and the entry."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from robot.errors import WorldError
from robot.world import builtin_worlds, load_world

BASE = """\
name = "test"
boundary = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]

[start]
x = 0.5
y = 0.5
theta_deg = 90.0
"""

ALL_SHAPES = (
    BASE
    + """
[[obstacles]]
shape = "rect"
center = [3.0, 2.0]
size = [0.8, 0.4]
angle_deg = 30.0

[[obstacles]]
shape = "circle"
center = [1.0, 2.0]
radius = 0.25

[[obstacles]]
shape = "ellipse"
center = [2.0, 1.0]
radii = [0.5, 0.2]
angle_deg = -20.0

[[obstacles]]
shape = "polygon"
points = [[3.2, 0.2], [3.8, 0.2], [3.8, 0.9]]
"""
)


def obstacle(body: str) -> str:
    return BASE + "\n[[obstacles]]\n" + body + "\n"


def write(tmp_path: Path, text: str, name: str = "world.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


BAD_WORLDS = {
    "invalid TOML": ("boundary = [[0.0, 0.0],,\n", "invalid TOML"),
    "duplicate key": ("name = 'again'\n" + BASE, "invalid TOML"),
    "missing boundary": (BASE.replace("boundary", "# boundary"), "boundary: missing key 'boundary'"),
    "boundary of two points": (
        BASE.replace("[[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]", "[[0.0, 0.0], [4.0, 0.0]]"),
        "boundary: 'boundary' must be a list of at least 3 points",
    ),
    "boundary not a list": (
        BASE.replace("[[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]", '"square"'),
        "boundary: 'boundary' must be a list",
    ),
    "bow-tie boundary": (
        BASE.replace(
            "[[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]", "[[0.0, 0.0], [4.0, 3.0], [4.0, 0.0], [0.0, 1.5]]"
        ),
        "boundary: polygon is not simple",
    ),
    "flat boundary": (
        BASE.replace("[[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]", "[[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]]"),
        "boundary: polygon has no area",
    ),
    "non-number coordinate": (BASE.replace("[4.0, 3.0]", '["4", 3.0]'), "boundary[2]: expected a point [x, y]"),
    "boolean coordinate": (BASE.replace("[4.0, 3.0]", "[true, 3.0]"), "boundary[2]: expected a point [x, y]"),
    "three-number point": (BASE.replace("[4.0, 3.0]", "[4.0, 3.0, 1.0]"), "boundary[2]: expected a point [x, y]"),
    "NaN coordinate": (BASE.replace("[4.0, 3.0]", "[nan, 3.0]"), "boundary[2]: expected a point [x, y]"),
    "NaN start": (BASE.replace("x = 0.5", "x = nan"), "start: 'x' must be a finite number, got nan"),
    "infinite radius": (
        obstacle('shape = "circle"\ncenter = [2.0, 2.0]\nradius = inf'),
        "obstacles[0]: 'radius' must be a finite",
    ),
    "infinite angle": (
        obstacle('shape = "rect"\ncenter = [2.0, 2.0]\nsize = [1.0, 1.0]\nangle_deg = -inf'),
        "obstacles[0]: 'angle_deg'",
    ),
    "huge coordinate": (BASE.replace("[4.0, 3.0]", "[1e300, 3.0]"), "boundary[2]: point [1e+300, 3.0] is out of range"),
    "unknown shape": (obstacle('shape = "star"\ncenter = [2.0, 2.0]'), "obstacles[0]: unknown shape 'star'"),
    "numeric shape": (obstacle("shape = 3"), "obstacles[0]: unknown shape 3"),
    "missing shape": (obstacle("center = [2.0, 2.0]"), "obstacles[0]: missing key 'shape'"),
    "rect without size": (obstacle('shape = "rect"\ncenter = [2.0, 2.0]'), "obstacles[0]: missing key 'size'"),
    "circle without center": (obstacle('shape = "circle"\nradius = 0.2'), "obstacles[0]: missing key 'center'"),
    "unknown obstacle key": (
        obstacle('shape = "circle"\ncenter = [2.0, 2.0]\nradius = 0.2\ncolour = "red"'),
        "obstacles[0]: unknown key 'colour' for shape 'circle'",
    ),
    "key of another shape": (
        obstacle('shape = "circle"\ncenter = [2.0, 2.0]\nradius = 0.2\nsize = [1.0, 1.0]'),
        "obstacles[0]: unknown key 'size'",
    ),
    "unknown top-level key": ("robot = 1\n" + BASE, "robot: unknown top-level key"),
    "unknown start key": (BASE + "z = 1.0\n", "start: unknown key 'z'"),
    "negative radius": (
        obstacle('shape = "circle"\ncenter = [2.0, 2.0]\nradius = -0.2'),
        "obstacles[0]: 'radius' must be positive",
    ),
    "zero size": (
        obstacle('shape = "rect"\ncenter = [2.0, 2.0]\nsize = [0.0, 1.0]'),
        "obstacles[0]: 'size' must be positive",
    ),
    "negative radii": (
        obstacle('shape = "ellipse"\ncenter = [2.0, 2.0]\nradii = [0.3, -0.1]'),
        "obstacles[0]: 'radii' must be positive",
    ),
    "self-intersecting polygon obstacle": (
        obstacle('shape = "polygon"\npoints = [[2.0, 1.0], [3.0, 2.0], [3.0, 1.0], [2.0, 1.5]]'),
        "obstacles[0]: polygon is not simple",
    ),
    "polygon obstacle of two points": (
        obstacle('shape = "polygon"\npoints = [[2.0, 1.0], [3.0, 2.0]]'),
        "obstacles[0]: 'points' must be a list of at least 3 points",
    ),
    "bad point in polygon obstacle": (
        obstacle('shape = "polygon"\npoints = [[2.0, 1.0], [3.0, 2.0], "x"]'),
        "obstacles[0].points[2]: expected a point",
    ),
    "second obstacle is bad": (
        obstacle('shape = "circle"\ncenter = [2.0, 2.0]\nradius = 0.2') + '\n[[obstacles]]\nshape = "blob"\n',
        "obstacles[1]: unknown shape 'blob'",
    ),
    "obstacles not tables": (
        BASE.replace('name = "test"', 'name = "test"\nobstacles = [1, 2]'),
        "obstacles[0]: expected a table",
    ),
    "start outside boundary": (BASE.replace("x = 0.5", "x = 4.5"), "start: (4.5, 0.5) is not inside the boundary"),
    "start on the boundary": (BASE.replace("x = 0.5", "x = 0.0"), "start: (0.0, 0.5) is not inside the boundary"),
    "start inside an obstacle": (
        obstacle('shape = "circle"\ncenter = [0.6, 0.6]\nradius = 0.3'),
        "start: (0.5, 0.5) is inside obstacles[0] (circle)",
    ),
    "missing start": (BASE.split("[start]")[0], "start: missing table [start]"),
    "start not a table": (BASE.split("[start]")[0] + "start = 5\n", "start: missing table [start]"),
    "start without theta": (BASE.replace("theta_deg = 90.0", ""), "start: missing key 'theta_deg'"),
    "start theta not a number": (
        BASE.replace("theta_deg = 90.0", 'theta_deg = "north"'),
        "start: 'theta_deg' must be a finite number",
    ),
    "empty name": (BASE.replace('name = "test"', 'name = "  "'), "name: must be a non-empty string"),
    "empty file": ("", "boundary: missing key 'boundary'"),
}


@pytest.mark.parametrize("case", list(BAD_WORLDS))
def test_bad_world_is_a_world_error_naming_file_and_entry(tmp_path: Path, case: str) -> None:
    text, entry = BAD_WORLDS[case]
    path = write(tmp_path, text)
    with pytest.raises(WorldError) as info:
        load_world(path)
    message = str(info.value)
    assert isinstance(info.value, ValueError)
    assert message.startswith(f"{path}: "), message
    assert entry in message, message
    assert "\n" not in message


def test_shape_given_as_a_list_is_a_world_error(tmp_path: Path) -> None:
    path = write(tmp_path, obstacle('shape = ["rect"]\ncenter = [2.0, 2.0]\nsize = [1.0, 1.0]'))
    with pytest.raises(WorldError, match=r"obstacles\[0\]: unknown shape"):
        load_world(path)


def test_non_utf8_file_is_a_world_error(tmp_path: Path) -> None:
    path = tmp_path / "latin1.toml"
    path.write_bytes(BASE.replace("test", "caf\xe9").encode("latin-1"))
    with pytest.raises(WorldError, match="cannot read"):
        load_world(path)


def test_directory_instead_of_file(tmp_path: Path) -> None:
    folder = tmp_path / "worlds.toml"
    folder.mkdir()
    with pytest.raises(WorldError, match="is a directory") as info:
        load_world(folder)
    assert str(folder) in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nowhere.toml"
    with pytest.raises(WorldError, match="no such world file") as info:
        load_world(path)
    assert str(path) in str(info.value)


def test_unknown_builtin_name_lists_the_known_ones() -> None:
    with pytest.raises(WorldError, match=r"room99: no such world file or built-in world \(built-in: .*room1") as info:
        load_world("room99")
    assert isinstance(info.value, ValueError)


def test_a_world_with_all_four_shapes_loads(tmp_path: Path) -> None:
    world = load_world(write(tmp_path, ALL_SHAPES))
    assert world.name == "test"
    assert [o.shape for o in world.obstacles] == ["rect", "circle", "ellipse", "polygon"]
    assert [o.index for o in world.obstacles] == [0, 1, 2, 3]
    rect, circle, ellipse, triangle = (o.polygon for o in world.obstacles)
    assert rect.area == pytest.approx(0.8 * 0.4)
    assert rect.centroid.x == pytest.approx(3.0) and rect.centroid.y == pytest.approx(2.0)
    assert rect.bounds[2] - rect.bounds[0] == pytest.approx(
        0.8 * math.cos(math.radians(30)) + 0.4 * math.sin(math.radians(30))
    )
    assert circle.area == pytest.approx(math.pi * 0.25**2, rel=1e-3)
    assert ellipse.area == pytest.approx(math.pi * 0.5 * 0.2, rel=1e-3)
    assert triangle.area == pytest.approx(0.5 * 0.6 * 0.7)
    assert world.start.x == 0.5 and world.start.y == 0.5
    assert world.start.theta == pytest.approx(math.pi / 2)
    assert world.bounds == (0.0, 0.0, 4.0, 3.0)
    assert world.free_space.area == pytest.approx(12.0 - sum(o.polygon.area for o in world.obstacles))
    assert world.segments.shape[1] == 4


def test_closing_point_repeated_is_accepted(tmp_path: Path) -> None:
    closed = BASE.replace("[0.0, 3.0]]", "[0.0, 3.0], [0.0, 0.0]]")
    assert load_world(write(tmp_path, closed)).boundary.area == pytest.approx(12.0)


def test_name_defaults_to_the_file_stem(tmp_path: Path) -> None:
    world = load_world(write(tmp_path, BASE.replace('name = "test"', ""), name="kitchen.toml"))
    assert world.name == "kitchen"


def test_every_builtin_world_loads_by_name_and_by_path() -> None:
    builtins = builtin_worlds()
    assert {"room1", "room2", "room3", "room4"} <= set(builtins)
    for name, path in builtins.items():
        by_name = load_world(name)
        by_path = load_world(path)
        assert by_name.boundary.equals(by_path.boundary)
        assert by_name.name == name
        assert by_name.boundary.contains(by_name.free_space.representative_point())
