"""World files (SPEC §1): loading, validation and the geometry the simulator and ground truth use."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely import affinity
from shapely.geometry import Point, Polygon
from shapely.validation import explain_validity

from robot.errors import WorldError
from robot.grid import GridSpec

WORLDS_DIR = Path(__file__).resolve().parent.parent / "config" / "worlds"
SHAPES = ("rect", "circle", "ellipse", "polygon")
CURVE_SEGMENTS = 96  # straight segments used for a circle or ellipse outline
MAX_WORLD_EXTENT_M = 200.0


@dataclass(frozen=True)
class Pose:
    x: float  # [m]
    y: float  # [m]
    theta: float  # heading [rad], counter-clockwise from +x


@dataclass(frozen=True)
class Obstacle:
    index: int
    shape: str
    polygon: Polygon


@dataclass(frozen=True)
class World:
    name: str
    description: str
    boundary: Polygon
    obstacles: tuple[Obstacle, ...]
    start: Pose
    source: str = ""
    _segments: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 4)), repr=False, compare=False)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(min_x, min_y, max_x, max_y) of the boundary [m]."""
        b = self.boundary.bounds
        return (b[0], b[1], b[2], b[3])

    def grid(self, resolution: float) -> GridSpec:
        """The map grid for this world (SPEC §2): origin at the bounding box's minimum corner."""
        return GridSpec.covering(*self.bounds, resolution)

    @property
    def free_space(self) -> Polygon:
        """The boundary minus every obstacle."""
        geom = self.boundary
        if self.obstacles:
            geom = geom.difference(shapely.union_all([o.polygon for o in self.obstacles]))
        return geom  # type: ignore[return-value]

    @property
    def segments(self) -> NDArray[np.float64]:
        """Every wall and obstacle edge as rows (x0, y0, x1, y1) [m], free space on each edge's left."""
        return self._segments


def _ring_segments(poly: Polygon, free_inside: bool) -> NDArray[np.float64]:
    """Edges of a polygon's outline, oriented so that free space lies on their left."""
    ring = poly.exterior
    pts = np.asarray(ring.coords)
    if ring.is_ccw != free_inside:
        pts = pts[::-1]
    return np.hstack([pts[:-1], pts[1:]])


def _build_segments(boundary: Polygon, obstacles: tuple[Obstacle, ...]) -> NDArray[np.float64]:
    parts = [_ring_segments(boundary, free_inside=True)]
    parts.extend(_ring_segments(o.polygon, free_inside=False) for o in obstacles)
    segs = np.vstack(parts)
    length = np.hypot(segs[:, 2] - segs[:, 0], segs[:, 3] - segs[:, 1])
    return np.ascontiguousarray(segs[length > 1e-12])


class _Reader:
    """Pulls typed values out of a parsed TOML table, naming the entry on failure."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, msg: str) -> WorldError:
        return WorldError(f"{self.source}: {where}: {msg}")

    def number(self, table: dict[str, Any], key: str, where: str) -> float:
        if key not in table:
            raise self.fail(where, f"missing key '{key}'")
        value = table[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(where, f"'{key}' must be a finite number, got {value!r}")
        if abs(value) > MAX_WORLD_EXTENT_M * 10:
            raise self.fail(where, f"'{key}' = {value} is out of range")
        return float(value)

    def point(self, value: Any, where: str) -> tuple[float, float]:
        if (
            not isinstance(value, list)
            or len(value) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
        ):
            raise self.fail(where, f"expected a point [x, y], got {value!r}")
        if max(abs(value[0]), abs(value[1])) > MAX_WORLD_EXTENT_M * 10:
            raise self.fail(where, f"point {value!r} is out of range")
        return (float(value[0]), float(value[1]))

    def pair(self, table: dict[str, Any], key: str, where: str, positive: bool = False) -> tuple[float, float]:
        if key not in table:
            raise self.fail(where, f"missing key '{key}'")
        p = self.point(table[key], f"{where}.{key}")
        if positive and (p[0] <= 0 or p[1] <= 0):
            raise self.fail(where, f"'{key}' must be positive, got {list(p)}")
        return p

    def points(self, table: dict[str, Any], key: str, where: str) -> list[tuple[float, float]]:
        if key not in table:
            raise self.fail(where, f"missing key '{key}'")
        value = table[key]
        if not isinstance(value, list) or len(value) < 3:
            raise self.fail(where, f"'{key}' must be a list of at least 3 points")
        label = key if where == key else f"{where}.{key}"
        return [self.point(v, f"{label}[{i}]") for i, v in enumerate(value)]

    def simple_polygon(self, pts: list[tuple[float, float]], where: str) -> Polygon:
        if len(pts) > 3 and pts[0] == pts[-1]:
            pts = pts[:-1]
        poly = Polygon(pts)
        if poly.convex_hull.area <= 1e-9:
            raise self.fail(where, "polygon has no area")
        if not poly.exterior.is_simple:
            raise self.fail(where, f"polygon is not simple ({explain_validity(poly)})")
        if poly.area <= 1e-9:
            raise self.fail(where, "polygon has no area")
        if not poly.is_valid:
            raise self.fail(where, f"polygon is not simple ({explain_validity(poly)})")
        return shapely.normalize(poly)  # type: ignore[return-value]


def _obstacle(reader: _Reader, table: Any, index: int) -> Obstacle:
    where = f"obstacles[{index}]"
    if not isinstance(table, dict):
        raise reader.fail(where, "expected a table")
    shape = table.get("shape")
    if shape is None:
        raise reader.fail(where, "missing key 'shape'")
    allowed: dict[str, set[str]] = {
        "rect": {"shape", "center", "size", "angle_deg"},
        "circle": {"shape", "center", "radius"},
        "ellipse": {"shape", "center", "radii", "angle_deg"},
        "polygon": {"shape", "points"},
    }
    if not isinstance(shape, str) or shape not in allowed:
        raise reader.fail(where, f"unknown shape {shape!r} (expected one of {', '.join(SHAPES)})")
    unknown = sorted(set(table) - allowed[shape])
    if unknown:
        raise reader.fail(where, f"unknown key '{unknown[0]}' for shape '{shape}'")
    poly: Polygon
    if shape == "polygon":
        poly = reader.simple_polygon(reader.points(table, "points", where), where)
    else:
        cx, cy = reader.pair(table, "center", where)
        angle = reader.number(table, "angle_deg", where) if "angle_deg" in table else 0.0
        if shape == "rect":
            w, h = reader.pair(table, "size", where, positive=True)
            poly = Polygon(
                [(cx - w / 2, cy - h / 2), (cx + w / 2, cy - h / 2), (cx + w / 2, cy + h / 2), (cx - w / 2, cy + h / 2)]
            )
        elif shape == "circle":
            r = reader.number(table, "radius", where)
            if r <= 0:
                raise reader.fail(where, f"'radius' must be positive, got {r}")
            poly = Point(cx, cy).buffer(r, quad_segs=CURVE_SEGMENTS // 4)
        else:
            rx, ry = reader.pair(table, "radii", where, positive=True)
            unit = Point(0.0, 0.0).buffer(1.0, quad_segs=CURVE_SEGMENTS // 4)
            poly = affinity.translate(affinity.scale(unit, rx, ry, origin=(0, 0)), cx, cy)
        if angle:
            poly = affinity.rotate(poly, angle, origin=(cx, cy))
    return Obstacle(index=index, shape=shape, polygon=poly)


def world_from_dict(data: dict[str, Any], source: str) -> World:
    """Validate a parsed world table and build the World (SPEC §1)."""
    reader = _Reader(source)
    known = {"name", "description", "boundary", "start", "obstacles"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise reader.fail(unknown[0], "unknown top-level key")
    name = data.get("name", Path(source).stem if source else "world")
    if not isinstance(name, str) or not name.strip():
        raise reader.fail("name", "must be a non-empty string")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise reader.fail("description", "must be a string")
    boundary = reader.simple_polygon(reader.points(data, "boundary", "boundary"), "boundary")
    min_x, min_y, max_x, max_y = boundary.bounds
    if max(max_x - min_x, max_y - min_y) > MAX_WORLD_EXTENT_M:
        raise reader.fail("boundary", f"world is larger than {MAX_WORLD_EXTENT_M:.0f} m")

    start_table = data.get("start")
    if not isinstance(start_table, dict):
        raise reader.fail("start", "missing table [start] with x, y, theta_deg")
    extra = sorted(set(start_table) - {"x", "y", "theta_deg"})
    if extra:
        raise reader.fail("start", f"unknown key '{extra[0]}'")
    start = Pose(
        reader.number(start_table, "x", "start"),
        reader.number(start_table, "y", "start"),
        math.radians(reader.number(start_table, "theta_deg", "start")),
    )

    raw_obstacles = data.get("obstacles", [])
    if not isinstance(raw_obstacles, list):
        raise reader.fail("obstacles", "must be an array of tables ([[obstacles]])")
    obstacles = tuple(_obstacle(reader, t, i) for i, t in enumerate(raw_obstacles))

    for o in obstacles:
        if not o.polygon.intersects(boundary):
            raise reader.fail(f"obstacles[{o.index}]", f"{o.shape} lies entirely outside the boundary")
    start_point = Point(start.x, start.y)
    if not boundary.contains(start_point):
        raise reader.fail("start", f"({start.x}, {start.y}) is not inside the boundary")
    for o in obstacles:
        if o.polygon.intersects(start_point):
            raise reader.fail("start", f"({start.x}, {start.y}) is inside obstacles[{o.index}] ({o.shape})")
    return World(
        name=name.strip(),
        description=description,
        boundary=boundary,
        obstacles=obstacles,
        start=start,
        source=source,
        _segments=_build_segments(boundary, obstacles),
    )


def builtin_worlds() -> dict[str, Path]:
    """Names and paths of the worlds shipped in ``config/worlds``."""
    return {p.stem: p for p in sorted(WORLDS_DIR.glob("*.toml"))}


def load_world_text(text: str, source: str) -> World:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise WorldError(f"{source}: invalid TOML: {exc}") from None
    return world_from_dict(data, source)


def load_world(path_or_name: str | Path) -> World:
    """Load a world by built-in name (``room1``) or by file path; errors name the file and entry."""
    text_name = str(path_or_name)
    builtins = builtin_worlds()
    if text_name in builtins:
        path = builtins[text_name]
    else:
        path = Path(path_or_name)
        if not path.exists():
            known = ", ".join(builtins) or "none"
            raise WorldError(f"{text_name}: no such world file or built-in world (built-in: {known})")
    if path.is_dir():
        raise WorldError(f"{path}: is a directory, expected a world TOML file")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise WorldError(f"{path}: cannot read: {exc}") from None
    return load_world_text(text, str(path))
