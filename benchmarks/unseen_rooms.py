"""Benchmark: whole runs in rooms nobody tuned against, generated at random from a seed.

Half the rooms are the kind people write by hand (coordinates on 5 cm: L- and T-shaped rooms,
corridors with side rooms, a partition with a doorway, clutter with chair legs), half are irregular
polygons with furniture at any angle (coordinates on 1 cm). One simulated run per room at the
default settings and noise; prints each room's scores and the spread over all of them, so that a
change can be checked against rooms it was not made for, and a failure (a run that ends early,
a large pose error) shows up with the world file that reproduces it (``--out DIR`` keeps them).

``--style furnished`` draws lived-in rooms instead (coordinates on 5 cm: boxes, L-shapes, large
halls, a corner cut at an angle): wardrobes and beds flush with a wall or pulled 10-30 cm out of it
(a slot the robot may just fit into), free-standing furniture at any angle, ellipses, round bins,
chair legs, corner wedges and small polygons, and a start heading of any whole degree.

    python benchmarks/unseen_rooms.py [--rooms 32] [--seed 1] [--style mixed|furnished]
                                      [--resolution 0.2] [--out DIR] [--config FILE]
"""

from __future__ import annotations

import argparse
import math
import random
import statistics
from pathlib import Path
from typing import Any

from shapely.affinity import rotate, scale
from shapely.geometry import Point, Polygon, box
from shapely.geometry.base import BaseGeometry
from shapely.ops import unary_union

from robot.errors import SonarSlamError
from robot.runner import simulate
from robot.settings import load_run_config
from robot.world import world_from_dict


def _q(value: float, step: float) -> float:
    return round(round(value / step) * step, 2)


def hand_written_room(rng: random.Random) -> tuple[str, BaseGeometry]:
    q = lambda v: _q(v, 0.05)  # noqa: E731
    kind = rng.choice(["L", "T", "corridor", "partition", "clutter"])
    if kind == "L":
        w, h = q(rng.uniform(4, 8)), q(rng.uniform(4, 7))
        cw, ch = q(rng.uniform(1.5, w - 1.5)), q(rng.uniform(1.5, h - 1.5))
        return kind, box(0, 0, w, h).difference(box(w - cw, h - ch, w, h))
    if kind == "T":
        w, h, sw, sh = q(rng.uniform(5, 8)), q(rng.uniform(1.2, 2.0)), q(rng.uniform(1.2, 2.0)), q(rng.uniform(2, 4))
        x = q(rng.uniform(0.5, w - sw - 0.5))
        return kind, unary_union([box(0, sh, w, sh + h), box(x, 0, x + sw, sh)])
    if kind == "corridor":
        length, width = q(rng.uniform(6, 10)), q(rng.uniform(1.0, 1.6))
        parts = [box(0, 0, length, width)]
        for _ in range(rng.randint(1, 3)):
            x, rw, rh = q(rng.uniform(0.5, length - 2)), q(rng.uniform(1.0, 2.0)), q(rng.uniform(1.0, 2.5))
            parts.append(box(x, width, x + rw, width + rh) if rng.random() < 0.5 else box(x, -rh, x + rw, 0))
        return kind, unary_union(parts)
    if kind == "partition":
        return kind, box(0, 0, q(rng.uniform(5, 8)), q(rng.uniform(3.5, 6)))
    return kind, box(0, 0, q(rng.uniform(3.5, 5.5)), q(rng.uniform(3.5, 5.5)))


def irregular_room(rng: random.Random) -> tuple[str, BaseGeometry]:
    n = rng.randint(5, 9)
    r0 = rng.uniform(1.8, 3.0)
    points = []
    for i in range(n):
        a = 2 * math.pi * i / n + rng.uniform(-0.25, 0.25)
        r = r0 * rng.uniform(0.75, 1.15)
        points.append((_q(r0 * 1.3 + r * math.cos(a), 0.01), _q(r0 * 1.3 + r * math.sin(a), 0.01)))
    return "polygon", Polygon(points)


def _rect(c: tuple[float, float], size: list[float], angle: float) -> tuple[dict[str, Any], BaseGeometry]:
    """A rect obstacle centred at ``c``, turned by ``angle`` degrees: its world-file entry and shape."""
    g = rotate(box(c[0] - size[0] / 2, c[1] - size[1] / 2, c[0] + size[0] / 2, c[1] + size[1] / 2), angle)
    return {"shape": "rect", "center": list(c), "size": size, "angle_deg": angle}, g


def furniture(rng: random.Random, kind: str, room: BaseGeometry) -> list[tuple[dict[str, Any], BaseGeometry]]:
    step = 0.01 if kind == "polygon" else 0.05
    min_x, min_y, max_x, max_y = room.bounds
    out: list[tuple[dict[str, Any], BaseGeometry]] = []
    if kind == "partition":  # a 10 cm wall across the room with a 70-100 cm doorway
        x, door = _q(rng.uniform(min_x + 1.5, max_x - 1.5), step), _q(rng.uniform(0.7, 1.0), step)
        y0 = _q(rng.uniform(0.5, max_y - door - 0.5), step)
        for lo, hi in ((min_y, y0), (y0 + door, max_y)):
            shape = {"shape": "rect", "center": [x, round((lo + hi) / 2, 3)], "size": [0.1, round(hi - lo, 3)]}
            out.append((shape, box(x - 0.05, lo, x + 0.05, hi)))
    count = {"clutter": rng.randint(5, 10), "corridor": rng.randint(0, 2)}.get(kind, rng.randint(1, 4))
    kinds = ["rect", "rect", "circle", "leg", "leg"] if kind == "clutter" else ["rect", "rect", "circle"]
    for _ in range(count):
        c = (_q(rng.uniform(min_x, max_x), step), _q(rng.uniform(min_y, max_y), step))
        pick = rng.choice(kinds)
        if pick == "rect":
            size = [_q(rng.uniform(0.3, 1.2), step), _q(rng.uniform(0.3, 0.8), step)]
            angle = rng.choice([0.0, 0.0, 90.0, float(round(rng.uniform(-40, 40)))])
            shape, g = _rect(c, size, angle)
        else:
            radius = 0.025 if pick == "leg" else _q(rng.uniform(0.1, 0.3), step)
            g = Point(c).buffer(radius)
            shape = {"shape": "circle", "center": list(c), "radius": radius}
        if room.contains(g):
            out.append((shape, g))
    return out


def furnished_room(rng: random.Random) -> tuple[str, BaseGeometry]:
    q = lambda v: _q(v, 0.05)  # noqa: E731
    kind = rng.choice(["box", "box", "L", "hall", "cut corner"])
    w, h = q(rng.uniform(3.5, 6.5)), q(rng.uniform(3.0, 5.5))
    if kind == "hall":
        w, h = q(rng.uniform(7, 9)), q(rng.uniform(5, 7))
    if kind == "L":
        cw, ch = q(rng.uniform(1.2, w / 2)), q(rng.uniform(1.2, h / 2))
        return kind, box(0, 0, w, h).difference(box(w - cw, h - ch, w, h))
    if kind == "cut corner":
        cut = q(rng.uniform(0.8, 1.8))
        return kind, Polygon([(0, 0), (w, 0), (w, h - cut), (q(w - cut * rng.uniform(0.6, 1.4)), h), (0, h)])
    return kind, box(0, 0, w, h)


def _against_wall(rng: random.Random, room: BaseGeometry) -> tuple[dict[str, Any], BaseGeometry]:
    """A wardrobe, bed or desk along one side of the room's bounding box: flush with it (its back a
    little past the wall), or pulled 10-30 cm out of it."""
    q = lambda v: _q(v, 0.05)  # noqa: E731
    min_x, min_y, max_x, max_y = room.bounds
    length, depth = q(rng.uniform(0.5, 2.0)), _q(rng.uniform(0.3, 0.9), 0.025)
    gap = _q(rng.uniform(0.1, 0.3), 0.01) if rng.random() < 0.4 else -0.05
    side = rng.randrange(4)
    if side < 2:
        x = q(rng.uniform(min_x, max_x - length))
        y0 = min_y + gap if side == 0 else max_y - gap - depth
        g = box(x, y0, x + length, y0 + depth)
    else:
        y = q(rng.uniform(min_y, max_y - length))
        x0 = min_x + gap if side == 2 else max_x - gap - depth
        g = box(x0, y, x0 + depth, y + length)
    b = g.bounds
    shape = {"shape": "rect", "center": [round((b[0] + b[2]) / 2, 3), round((b[1] + b[3]) / 2, 3)],
             "size": [round(b[2] - b[0], 3), round(b[3] - b[1], 3)], "angle_deg": 0.0}  # fmt: skip
    return shape, g


def furnishings(rng: random.Random, room: BaseGeometry) -> list[tuple[dict[str, Any], BaseGeometry]]:
    min_x, min_y, max_x, max_y = room.bounds
    out: list[tuple[dict[str, Any], BaseGeometry]] = []
    for _ in range(rng.randint(2, 7)):
        pick = rng.choice(["wall", "wall", "rect", "ellipse", "circle", "polygon", "wedge"])
        c = (_q(rng.uniform(min_x, max_x), 0.05), _q(rng.uniform(min_y, max_y), 0.05))
        shape: dict[str, Any]
        if pick == "wall":
            shape, g = _against_wall(rng, room)
        elif pick == "rect":
            size = [_q(rng.uniform(0.3, 1.2), 0.05), _q(rng.uniform(0.3, 0.8), 0.05)]
            angle = float(rng.choice([0, 90, rng.randint(-60, 60)]))
            shape, g = _rect(c, size, angle)
        elif pick == "ellipse":
            radii = [_q(rng.uniform(0.2, 0.7), 0.05), _q(rng.uniform(0.15, 0.45), 0.05)]
            angle = float(rng.randint(-90, 90))
            g = rotate(scale(Point(c).buffer(1.0, 64), radii[0], radii[1]), angle)
            shape = {"shape": "ellipse", "center": list(c), "radii": radii, "angle_deg": angle}
        elif pick == "circle":
            radius = rng.choice([0.02, 0.03, _q(rng.uniform(0.1, 0.35), 0.05)])
            g = Point(c).buffer(radius, 64)
            shape = {"shape": "circle", "center": list(c), "radius": radius}
        else:
            if pick == "wedge":  # a corner filled at an angle: a cupboard, a triangular shelf
                cx, cy = rng.choice([min_x, max_x]), rng.choice([min_y, max_y])
                a, b = rng.uniform(0.4, 1.0), rng.uniform(0.4, 1.0)
                points = [(cx, cy), (cx + (a if cx == min_x else -a), cy), (cx, cy + (b if cy == min_y else -b))]
            else:
                n, r0 = rng.randint(3, 6), rng.uniform(0.25, 0.6)
                cx, cy = rng.uniform(min_x + 0.5, max_x - 0.5), rng.uniform(min_y + 0.5, max_y - 0.5)
                points = [
                    (cx + r0 * rng.uniform(0.6, 1.2) * math.cos(2 * math.pi * i / n + rng.uniform(-0.3, 0.3)),
                     cy + r0 * rng.uniform(0.6, 1.2) * math.sin(2 * math.pi * i / n + rng.uniform(-0.3, 0.3)))
                    for i in range(n)
                ]  # fmt: skip
            points = [(round(x, 2), round(y, 2)) for x, y in points]
            g = Polygon(points)
            if not g.is_valid or g.area < 0.02:
                continue
            shape = {"shape": "polygon", "points": [list(p) for p in points]}
        if g.intersection(room).area >= 0.01:
            out.append((shape, g))
    return out


def random_world(rng: random.Random, name: str, style: str = "mixed") -> dict[str, Any] | None:
    """A world dict in the world-file format, or None when this draw gave no usable room. ``style``
    is "mixed" (hand-written kinds and irregular polygons) or "furnished" (see the module's text)."""
    if style == "furnished":
        kind, room = furnished_room(rng)
    else:
        kind, room = hand_written_room(rng) if rng.random() < 0.5 else irregular_room(rng)
    if room.geom_type != "Polygon" or not room.is_valid:
        return None
    room = room.simplify(0.001)
    pieces = furnishings(rng, room) if style == "furnished" else furniture(rng, kind, room)
    free = room
    for _, g in pieces:
        free = free.difference(g)
    min_x, min_y, max_x, max_y = room.bounds
    for _ in range(300):
        start = Point(_q(rng.uniform(min_x, max_x), 0.05), _q(rng.uniform(min_y, max_y), 0.05))
        if free.contains(start.buffer(0.35)):
            break
    else:
        return None

    def shift(p: tuple[float, float] | list[float]) -> list[float]:
        return [round(p[0] - min_x, 3), round(p[1] - min_y, 3)]

    def moved(shape: dict[str, Any]) -> dict[str, Any]:
        if "points" in shape:
            return {**shape, "points": [shift(p) for p in shape["points"]]}
        return {**shape, "center": shift(shape["center"])}

    heading = float(rng.randint(-180, 179)) if style == "furnished" else float(rng.choice([0, 90, 180, -90]))
    return {
        "name": name,
        "description": f"generated: {kind}",
        "boundary": [shift(p) for p in list(room.exterior.coords)[:-1]],
        "start": {"x": round(start.x - min_x, 3), "y": round(start.y - min_y, 3), "theta_deg": heading},
        "obstacles": [moved(shape) for shape, _ in pieces],
    }


def to_toml(world: dict[str, Any]) -> str:
    def value(v: Any) -> str:
        return f'"{v}"' if isinstance(v, str) else str(v)

    lines = [f"{k} = {value(world[k])}" for k in ("name", "description", "boundary")]
    lines += ["", "[start]"] + [f"{k} = {v}" for k, v in world["start"].items()]
    for shape in world["obstacles"]:
        lines += ["", "[[obstacles]]"] + [f"{k} = {value(v)}" for k, v in shape.items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rooms", type=int, default=32, help="how many rooms (default 32)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the room generator (default 1)")
    parser.add_argument("--style", choices=("mixed", "furnished"), default="mixed", help="default mixed")
    parser.add_argument("--resolution", type=float, default=None, help="map cell side [m] (default: the settings')")
    parser.add_argument("--out", type=Path, default=None, help="keep each room's world file here")
    parser.add_argument("--config", type=Path, default=None, help="a settings file, as `sonarslam run --config`")
    args = parser.parse_args(argv)
    if args.resolution is not None and not (math.isfinite(args.resolution) and args.resolution > 0):
        parser.error(f"argument --resolution: must be a positive number, got {args.resolution}")
    rng = random.Random(args.seed)
    try:
        cfg = load_run_config(args.config, {"resolution": args.resolution})
    except SonarSlamError as exc:
        parser.error(str(exc))
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
    print(f"{'room':<22s} {'F1':>6s} {'recall':>6s} {'steps':>6s} {'ended by':<11s} {'xy cm':>6s} {'deg':>5s}")
    rows = []
    prefix = "unseen" if args.style == "mixed" else "furnished"
    while len(rows) < args.rooms:
        data = random_world(rng, f"{prefix}{args.seed}_{len(rows)}", args.style)
        if data is None:
            continue
        try:
            world = world_from_dict(data, f"{data['name']}.toml")
        except SonarSlamError:
            continue  # a draw the world checks refuse (an obstacle touching the start, ...)
        if args.out is not None:
            (args.out / f"{data['name']}.toml").write_text(to_toml(data))
        r = simulate(world, cfg.robot, cfg.noise, cfg.slam, seed=0)
        label = f"{data['name']} ({data['description'].split(': ')[1]})"
        xy_cm = 100 * r.final_xy_error_m
        print(f"{label:<22s} {r.metrics.f1:6.3f} {r.metrics.recall:6.3f} {r.steps:6d} {r.terminated_by:<11s} "
              f"{xy_cm:6.1f} {r.final_theta_error_deg:5.2f}", flush=True)  # fmt: skip
        rows.append((r.metrics.f1, xy_cm, data["description"].endswith("polygon")))
    groups = [("all", lambda row: True)]
    if args.style == "mixed":
        groups += [("hand-written kinds", lambda row: not row[2]), ("irregular polygons", lambda row: row[2])]
    for title, pick in groups:
        f1s = sorted(row[0] for row in rows if pick(row))
        xys = [row[1] for row in rows if pick(row)]
        if f1s:
            p10 = f1s[max(0, math.ceil(0.1 * len(f1s)) - 1)]
            print(f"{title}: {len(f1s)} rooms, F1 median {statistics.median(f1s):.3f}, 10th percentile {p10:.3f}, "
                  f"worst {f1s[0]:.3f}; final position error median {statistics.median(xys):.1f} cm, "
                  f"worst {max(xys):.1f} cm")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
