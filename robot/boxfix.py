"""Position fixes from the room's surveyed box: a side sonar that meets a box edge head-on measures
the robot's distance to that wall, which bounds dead-reckoning drift along that axis.

Only used when the map size is known (the paper's setting). A reading counts when the beam points
within a few degrees of an axis, the echo is short and strong, and the wall it implies lies within a
few centimetres of the box edge; anything else (furniture against the wall, a glancing echo) is
ignored. In a room that is not a rectangle its walls touch the box only at vertices, so a reading
also needs the map to show the wall on the edge along a stretch, not one that comes close to it.

Drift grows with the distance driven, and once it has passed a fixed gate the fixes would stop for
good (in a large hall the heading drifts during long crossings of open floor). ``DriftGate`` widens
the gate with the distance driven since an axis's last fix; a reading past the fixed gate counts
only when the edge's last such readings, taken along a stretch of it, agree on one offset, as a
drifted estimate makes them, and not on offsets that change along the edge, as an angled wall near
the edge does. A reading that puts the wall beyond the box edge, where no wall of the room can be,
says that the estimate has drifted towards that wall: its gate grows further
(``outside_gate_m``), and it needs only that agreement, not the map, which a drifted estimate drew
with the wall where the drift put it. A reading that puts the wall inside the edge may be a drift
away from the wall, or furniture or a slanted wall in front of it; it may do without the map only
when the estimate can have drifted that far by its own doubt, the map from before the drift showed
nothing there, and the readings were taken along a long straight stretch in one pass
(``inside_fix``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator

from robot.config import RobotConfig
from robot.mapping.base import Evidence, MapFrame
from robot.mapping.geometry import place_beams
from robot.world import Pose


class BoxFixConfig(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    enabled: bool = True
    axis_tolerance_deg: float = Field(default=2.0, gt=0.0, le=20.0)  # beam within this of an axis
    max_range_m: float = Field(default=1.2, gt=0.0)  # only short echoes
    # Tight gate, small gain: in a room that is not a rectangle an angled wall can pass close to the
    # box edge, and a loose gate let such echoes drag the estimate (hexagon: 27 cm of error at 12 cm).
    gate_m: float = Field(default=0.05, gt=0.0)  # the implied wall must be this close to the box edge
    gain: float = Field(default=0.3, gt=0.0, le=1.0)  # share of the offset corrected per sweep
    # The gate grows by gate_growth per metre driven since the axis's last fix, up to max_gate_m
    # (see DriftGate; a growth of 0 keeps the gate fixed) ...
    gate_growth: float = Field(default=0.02, ge=0.0)
    max_gate_m: float = Field(default=0.15, gt=0.0)
    # ... except for readings that put the wall beyond the box edge, where no wall of the room can be:
    # their gate grows the same way up to outside_gate_m, and past gate_m they need no map check,
    # only the agreement along the edge below (the map drawn by a drifted estimate shows the wall
    # where the drift put it, so it cannot confirm the edge; 0 turns this off).
    outside_gate_m: float = Field(default=0.5, ge=0.0)
    # ... and readings that put the wall inside the box edge past gate_m, which the map so far and the
    # map at the axis's last fix refuse (the robot reaches a wall for the first time after a long
    # crossing of open floor, its estimate already drifted away from it): with inside_fix they count
    # when the axis has had a fix (its map from before the drift shows no face where the readings
    # put the wall, across inside_seen_band_m), the offset is within inside_sigmas of the drift that
    # the heading's doubt allows since that fix (``DriftGate.drift``; plus inside_scale of the
    # distance driven along the axis, for the wheels), and the edge's last inside_readings such
    # readings were taken in one pass along it over inside_span_m, on a line within inside_rms_m
    # whose slope is at most inside_max_slope (or what the heading's doubt explains, below). A
    # slanted wall near a vertex on the edge, or a wall that bulges towards it, gives readings as
    # flat as a drift's (a beam's nearest echo), so the drift bound and the map from before are what
    # tell them apart.
    inside_fix: bool = True
    inside_sigmas: float = Field(default=3.0, gt=0.0)
    inside_scale: float = Field(default=0.005, ge=0.0)
    inside_seen_band_m: tuple[float, float] = (0.01, 0.04)
    inside_readings: int = Field(default=8, ge=3)
    inside_span_m: float = Field(default=1.2, ge=0.0)
    inside_rms_m: float = Field(default=0.015, ge=0.0)
    inside_max_slope: float = Field(default=0.01, ge=0.0)
    # ... or at most inside_slope_sigmas times the heading's doubt (as a slope): driving along a wall
    # with the heading off by delta, the estimate drifts across it by delta per metre, so a drift's
    # readings in one pass lie on a line of that slope (0 keeps inside_max_slope alone). With the
    # span's slack below: 30 built-in worlds x 3 seeds 0.9805 -> 0.9811 (largehall seed 1 0.916 ->
    # 0.981; 2 down, by 0.004 and 0.006), furnished `--seed 7712` 0.9796 -> 0.9824 (a hall 0.904 ->
    # 1.000, one room -0.007), four other batches of 32 rooms and Table I unchanged or up.
    inside_slope_sigmas: float = Field(default=2.0, ge=0.0)
    # ... and none of those readings lies within inside_clear_m along the edge of where a reading
    # last put the wall within gate_m of it (0 turns this off): a wall that leaves the edge a few
    # centimetres a metre from a vertex on it (a generated polygon's west wall, 2.6 degrees off the
    # edge) reads on the edge there and inside it further along, in one pass, on a line as flat as
    # the readings' noise lets a drift's be; a drift away from the wall after a long crossing is
    # found on a stretch of it where no reading was on the edge. Mixed `--seed 9911` room 4
    # (seed 0) 0.930 -> 0.976: a 7.75 cm "drift" taken off that wall had put the estimate 9-13 cm off.
    # 30 built-in worlds x 3 seeds, mixed 1311, furnished 9912: no run changed.
    inside_clear_m: float = Field(default=0.6, ge=0.0)
    # The spans (inside_span_m, wide_span_m) are measured between estimated positions, which the
    # robot's cell centres put a centimetre or so either side of a whole number of cells: this much
    # short still counts (a pass over seven cells read 1.1976 m, short of 1.2).
    span_slack_m: float = Field(default=0.01, ge=0.0)
    # ... and a reading past gate_m counts only when the edge's last wide_readings such readings span
    # wide_span_m along it and lie on a line within wide_rms_m whose slope is at most wide_max_slope.
    wide_readings: int = Field(default=6, ge=3)
    wide_span_m: float = Field(default=0.6, ge=0.0)
    wide_rms_m: float = Field(default=0.02, ge=0.0)
    wide_max_slope: float = Field(default=0.03, ge=0.0)
    # Such a fix corrects its whole offset at once, and the map is rebuilt with the drift spread over
    # the distance driven since the axis's last fix (robot.mapping.journal); false: it corrects by
    # ``gain`` per sweep like any other, and the map keeps what was marked while the estimate was off.
    drift_repair: bool = True
    # The map so far must show the box edge itself as a wall across most of the beam's footprint:
    # in a room that is not a rectangle a corner or an angled wall may touch the box edge at one
    # point, and echoes from near that point would drag the estimate.
    edge_support: float = Field(default=0.7, ge=0.0, le=1.0)  # share of the footprint seen solid
    edge_band_m: tuple[float, float] = (0.02, 0.06)  # solid evidence counts this far inside / outside the edge
    occupied_logodds: float = Field(default=0.8, gt=0.0)  # evidence that counts as solid
    # A bump while driving towards a box wall (within this angle of head-on), with the body this
    # close to touching it by the estimate, is that wall: a position fix (0 turns this off). Wider
    # than the sonar gate: a bump is unambiguous, and it comes when the estimate is off the most.
    contact_gate_m: float = Field(default=0.15, ge=0.0)
    contact_max_angle_deg: float = Field(default=50.0, gt=0.0, lt=90.0)
    # ... and only where the map shows that edge as a wall over +-this along it (at least the body's
    # width; the box's own corners end it). Where two walls of a room that is not a box meet at a
    # corner on a box edge, echo arcs smear the corner along the edge over about the body's width,
    # and a bump into either wall, short of the edge, was taken for the box wall.
    contact_support_m: float = Field(default=0.5, ge=0.0)
    # ... and only within the drift that the distance driven since the axis's last fix allows (the
    # sonar fixes' gate, ``DriftGate``), plus contact_spare_m. Just after a fix the estimate is
    # within centimetres across the wall; a bump 10-15 cm short of the box edge then is a wall of a
    # room that is not a rectangle, near a vertex on the edge, and taking it for the box wall moved
    # the estimate by as much (a generated polygon ended 17 cm off).
    contact_spare_m: float = Field(default=0.02, ge=0.0)
    # The map must show the wall on the edge along +-along_window_m (clipped to the box), not a
    # wall that comes close to it: in a room that is not a rectangle, a wall a few degrees off an
    # axis meets the box edge at a vertex, and near it passes the footprint check a few centimetres
    # inside the edge. Seen from the room, the first solid evidence may lie inner_band_m in from the
    # edge (past the evidence cell at the edge) along at most max_inner_share of the stretch (a
    # window of 0 turns this off). A bump needs the same to be a fix.
    along_window_m: float = Field(default=0.6, ge=0.0)
    inner_band_m: tuple[float, float] = (0.05, 0.15)
    max_inner_share: float = Field(default=0.08, ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _gates(self) -> BoxFixConfig:
        if self.max_gate_m < self.gate_m:
            raise ValueError("max_gate_m must be at least gate_m")
        return self


def _solid_near_edge(
    evidence: Evidence,
    hit: tuple[float, float],
    horizontal: bool,
    along: NDArray[np.float64],
    across: NDArray[np.float64],
    config: BoxFixConfig,
) -> NDArray[np.bool_]:
    """Whether the evidence is solid at each point of a grid laid on the box edge through ``hit``:
    ``along`` the edge and ``across`` it (+x or +y) [m], offsets from ``hit``, (along, across).

    ``horizontal``: the beam runs along x (the edge is a vertical line). The row of a point depends
    on its y alone and the column on its x, so each is converted once per line of points."""
    g = evidence.grid
    if horizontal:
        _, cols = g.world_to_index(hit[0] + across, np.full(across.size, hit[1]))
        rows, _ = g.world_to_index(np.full(along.size, hit[0]), hit[1] + along)
        rows, cols = rows[:, None], cols[None, :]
    else:
        _, cols = g.world_to_index(hit[0] + along, np.full(along.size, hit[1]))
        rows, _ = g.world_to_index(np.full(across.size, hit[0]), hit[1] + across)
        rows, cols = rows[None, :], cols[:, None]
    inside = g.contains_index(rows, cols)
    return inside & (
        evidence.logodds[np.clip(rows, 0, g.rows - 1), np.clip(cols, 0, g.cols - 1)] >= config.occupied_logodds
    )


def _on_edge(
    along: NDArray[np.float64], hit: tuple[float, float], horizontal: bool, span: tuple[float, float]
) -> NDArray[np.float64]:
    """The offsets of ``along`` that stay on the edge's own extent ``span``."""
    at = hit[1] if horizontal else hit[0]
    return along[(at + along >= span[0]) & (at + along <= span[1])]


def edge_supported(
    evidence: Evidence,
    hit: tuple[float, float],
    horizontal: bool,
    outward: float,
    half_width: float,
    config: BoxFixConfig,
    span: tuple[float, float] | None = None,
    band: tuple[float, float] | None = None,
) -> bool:
    """Whether the evidence shows a wall along the box edge through ``hit`` over +-``half_width``
    (clipped to ``span``, the edge's own extent along it, when given), solid within ``band`` (inside,
    outside; default ``config.edge_band_m``) of it.

    ``horizontal``: the beam runs along x (the edge is a vertical line); ``outward``: +1 or -1, the
    direction out of the box along the beam.
    """
    f = evidence.grid.resolution
    along = np.arange(-half_width, half_width + 1e-9, f)
    if span is not None:
        along = _on_edge(along, hit, horizontal, span)
        if along.size == 0:
            return False
    inside, outside = config.edge_band_m if band is None else band
    across = np.arange(-inside, outside + 1e-9, f / 2) * outward
    solid = _solid_near_edge(evidence, hit, horizontal, along, across, config)
    return bool(np.count_nonzero(np.any(solid, axis=1)) / along.size >= config.edge_support)


def runs_along_edge(
    evidence: Evidence,
    hit: tuple[float, float],
    horizontal: bool,
    outward: float,
    config: BoxFixConfig,
    span: tuple[float, float],
) -> bool:
    """Whether the wall that the evidence shows through ``hit`` runs along the box edge over
    +-``config.along_window_m`` (clipped to ``span``, the edge's extent), rather than coming close
    to it at one place (see ``BoxFixConfig``)."""
    f = evidence.grid.resolution
    along = _on_edge(np.arange(-config.along_window_m, config.along_window_m + 1e-9, f / 2), hit, horizontal, span)
    if along.size == 0:
        return True
    inner, deepest = config.inner_band_m
    # Depth from the edge, negative inside the room, from a cell deeper than the inner band out to
    # the edge band's outer side: two points per evidence cell, off the cells' edges (a box edge on
    # one would leave a point on it in either cell, by rounding).
    across = np.arange(-deepest - f + f / 4, config.edge_band_m[1], f / 2)
    solid = _solid_near_edge(evidence, hit, horizontal, along, across * outward, config)
    seen = np.any(solid, axis=1)
    face = np.where(seen, across[np.argmax(solid, axis=1)], np.nan)  # first solid seen from the room
    within = int(np.count_nonzero((face < -inner) & (face >= -deepest)))
    return within <= config.max_inner_share * along.size


_SPARE_M = 0.02  # what a fix past the fixed gate leaves to later sweeps, plus this, stays in the gate


class DriftGate:
    """How far from a box edge a reading may put the wall, as drift grows with the distance driven:
    the fixed gate plus ``gate_growth`` per metre driven since the axis's last fix, up to
    ``max_gate_m``. Past the fixed gate a reading counts only when the edge's last few such readings,
    taken along a stretch of it, agree on one offset (see the module's docstring)."""

    def __init__(self, config: BoxFixConfig) -> None:
        self.config = config
        self.travel = [0.0, 0.0]  # metres driven since the last fix along x and along y
        # How far the estimate can have drifted along x and y since the last fix, at one sigma of the
        # heading's doubt [m]: each step across an axis moves the estimate along it by the step times
        # the heading error; ``inside_scale`` of each step along it is the wheels' share.
        self.drift = [0.0, 0.0]
        self._at: tuple[float, float] | None = None
        self.theta_std = 0.0  # the heading's doubt when last driven [rad]
        # The edge's last readings past the fixed gate, (along, offset) per edge: those that the
        # map checks passed, and those that only ``inside_fix`` may count.
        self._wide: list[list[tuple[float, float]]] = [[], [], [], []]
        self._inside: list[list[tuple[float, float]]] = [[], [], [], []]
        self._on_edge: list[float | None] = [None, None, None, None]  # each edge's last reading within gate_m, along it

    def follow(self, x: float, y: float, drove: bool = True, theta_std: float = 0.0) -> None:
        """The estimate is now at (x, y): driven there with ``theta_std`` [rad] of doubt in its
        heading (kept for ``admits``), or moved there by a fix (``drove`` False)."""
        if drove:
            self.theta_std = theta_std
        if drove and self._at is not None:
            dx, dy = abs(x - self._at[0]), abs(y - self._at[1])
            step = math.hypot(dx, dy)
            self.travel = [t + step for t in self.travel]
            k = self.config.inside_scale
            self.drift = [self.drift[0] + dy * theta_std + k * dx, self.drift[1] + dx * theta_std + k * dy]
        self._at = (x, y)

    def _grown(self, axis: int) -> float:
        """The fixed gate grown by the distance driven along ``axis`` since its last fix [m]."""
        return self.config.gate_m + self.config.gate_growth * self.travel[axis]

    def limit(self, axis: int) -> float:
        """The gate for readings along ``axis`` (0: x, 1: y) [m]."""
        return min(self.config.max_gate_m, self._grown(axis))

    def outside_limit(self, axis: int) -> float:
        """The gate for readings along ``axis`` that put the wall beyond the box edge [m]."""
        c = self.config
        return min(max(c.max_gate_m, c.outside_gate_m), self._grown(axis))

    def fixed(self, axis: int, remaining_m: float) -> None:
        """A fix along ``axis`` that leaves ``remaining_m`` of its offset to later sweeps: the gate
        stays wide enough for that, with 2 cm to spare, so that a fix past the fixed gate can finish
        its correction."""
        c = self.config
        need = abs(remaining_m) + _SPARE_M - c.gate_m
        self.travel[axis] = max(0.0, need) / c.gate_growth if c.gate_growth > 0.0 else 0.0
        self.drift[axis] = abs(remaining_m) / c.inside_sigmas

    def admits(self, edge: int, along_m: float, offset: float, inside: bool = False) -> bool:
        """Whether a reading of ``edge`` (0-3: max x, min x, max y, min y) at ``along_m`` along it,
        within ``limit`` and passing the map's checks (or, with ``inside``, counted as a drift away
        from the wall: ``BoxFixConfig.inside_fix``), counts."""
        c = self.config
        if abs(offset) <= c.gate_m:
            self._wide[edge].clear()
            self._inside[edge].clear()
            self._on_edge[edge] = along_m
            return True
        kept = self._inside[edge] if inside else self._wide[edge]
        count = c.inside_readings if inside else c.wide_readings
        kept.append((along_m, offset))
        del kept[:-count]
        if len(kept) < count:
            return False
        at = np.array(kept)
        if np.ptp(at[:, 0]) < (c.inside_span_m if inside else c.wide_span_m) - c.span_slack_m:
            return False
        if inside:
            # In one pass along the edge, as a robot reaching a wall after a drift drives along it:
            # the readings of a curved or slanted wall near the edge, taken on the way back and forth
            # past it, can line up as flat as a drift's.
            steps = np.diff(at[:, 0])
            if not (np.all(steps >= -1e-9) or np.all(steps <= 1e-9)):
                return False
            # Close along the edge to where a reading was last on it: a wall leaving the edge.
            last = self._on_edge[edge]
            if (
                c.inside_clear_m > 0.0
                and last is not None
                and float(np.min(np.abs(at[:, 0] - last))) < c.inside_clear_m
            ):
                return False
        slope, intercept = np.polyfit(at[:, 0], at[:, 1], 1)
        rms = float(np.sqrt(np.mean((at[:, 1] - (slope * at[:, 0] + intercept)) ** 2)))
        if inside:
            max_slope = max(c.inside_max_slope, c.inside_slope_sigmas * math.tan(self.theta_std))
            return abs(slope) <= max_slope and rms <= c.inside_rms_m
        return abs(slope) <= c.wide_max_slope and rms <= c.wide_rms_m


def _may_fix_inside(
    config: BoxFixConfig,
    gate: DriftGate,
    offset: float,
    before: Evidence | None,
    hit: tuple[float, float],
    horizontal: bool,
    outward: float,
    foot: float,
) -> bool:
    """Whether a reading past the fixed gate that puts the wall ``offset`` inside the box edge at
    ``hit``, which the maps refuse, may count as a drift away from the wall
    (``BoxFixConfig.inside_fix``): ``before`` is the map at the axis's last fix within the gate, None
    if it has had none; ``outward`` (+1 or -1) the direction out of the box along the beam."""
    if not config.inside_fix or before is None or offset * outward <= config.gate_m:
        return False
    axis = 0 if horizontal else 1
    if abs(offset) > config.inside_sigmas * gate.drift[axis]:
        return False
    face = (hit[0] - offset, hit[1]) if horizontal else (hit[0], hit[1] - offset)
    return not edge_supported(before, face, horizontal, outward, foot, config, band=config.inside_seen_band_m)


def map_shows_edge(
    evidence: Evidence,
    hit: tuple[float, float],
    horizontal: bool,
    outward: float,
    half_width: float,
    config: BoxFixConfig,
    span: tuple[float, float],
    clip_to_span: bool = False,
) -> bool:
    """The map's checks on a sonar reading or a bump at ``hit``: the box edge solid over
    +-``half_width`` (the beam's footprint, or the body's support; clipped to ``span``, the edge's
    extent, with ``clip_to_span``) and the wall on the edge along a stretch."""
    if not edge_supported(evidence, hit, horizontal, outward, half_width, config, span if clip_to_span else None):
        return False
    return config.along_window_m <= 0.0 or runs_along_edge(evidence, hit, horizontal, outward, config, span)


def _median(values: list[float]) -> float:
    """np.median of a short list (the middle value, or the mean of the two middle ones) without its
    overhead: the same arithmetic."""
    ordered = sorted(values)
    mid = len(ordered) // 2
    return ordered[mid] if len(ordered) % 2 else (ordered[mid - 1] + ordered[mid]) / 2.0


def box_offsets(
    frame: MapFrame,
    robot: RobotConfig,
    pose: Pose,
    ranges_m: NDArray[np.float64],
    config: BoxFixConfig,
    evidence: Evidence | None = None,
    gate: DriftGate | None = None,
    trusted: tuple[Evidence | None, Evidence | None] | None = None,
) -> tuple[float | None, float | None]:
    """The position error (true minus estimated) [m] along x and along y that the box's walls show
    in one sweep (the median over the beams that count), or None for an axis no beam measured.

    With ``evidence`` (the map so far), a reading counts only where the map already shows the box
    edge as a wall across the beam's footprint, and on the edge along a longer stretch, not only
    where a wall comes close to it. With ``gate``, the gate grows with the distance driven (see
    ``DriftGate``); without it, it is ``config.gate_m``. ``trusted`` holds, per axis, the map as it
    was at that axis's last fix within ``gate_m``: a reading past that gate that the map so far
    refuses counts when that map shows the edge (the map so far may show the wall where the drifted
    estimate put it), or, when it puts the wall inside the edge, as ``BoxFixConfig.inside_fix`` says.
    """
    if frame.extent is None or not config.enabled:
        return None, None
    min_x, min_y, max_x, max_y = frame.extent
    tol = math.radians(config.axis_tolerance_deg)
    half = math.radians(robot.sonar.beam_width_deg) / 2.0
    dxs: list[float] = []
    dys: list[float] = []
    for beam in place_beams(pose, ranges_m, robot):
        if not beam.echo or beam.range_m > config.max_range_m:
            continue
        axis = math.remainder(beam.axis_rad, 2 * math.pi)
        for index, (target, horizontal, edge) in enumerate(
            ((0.0, True, max_x), (math.pi, True, min_x), (math.pi / 2, False, max_y), (-math.pi / 2, False, min_y))
        ):
            if abs(math.remainder(axis - target, 2 * math.pi)) > tol:
                continue
            if horizontal:
                offset = edge - (beam.x + beam.range_m * math.cos(axis))
            else:
                offset = edge - (beam.y + beam.range_m * math.sin(axis))
            xy = 0 if horizontal else 1
            inside = False  # refused by the maps, counted as a drift away from the wall (``inside_fix``)
            outward = 1.0 if target in (0.0, math.pi / 2) else -1.0
            # The wall beyond the box edge, where no wall of the room can be: the estimate has
            # drifted towards that wall.
            beyond = (
                gate is not None
                and config.outside_gate_m > 0.0
                and offset * outward < -config.gate_m
                and abs(offset) <= gate.outside_limit(xy)
            )
            if abs(offset) > (config.gate_m if gate is None else gate.limit(xy)) and not beyond:
                continue
            if evidence is not None and not beyond:
                hit = (edge, beam.y) if horizontal else (beam.x, edge)
                span = (min_y, max_y) if horizontal else (min_x, max_x)
                foot = beam.range_m * math.tan(half)
                if not map_shows_edge(evidence, hit, horizontal, outward, foot, config, span):
                    # Past the fixed gate the estimate may have drifted, and the map with it: the map
                    # as it was at the axis's last fix within the gate may show the edge instead.
                    old = None if trusted is None or abs(offset) <= config.gate_m else trusted[xy]
                    if old is None or not map_shows_edge(old, hit, horizontal, outward, foot, config, span):
                        inside = gate is not None and _may_fix_inside(
                            config, gate, offset, old, hit, horizontal, outward, foot
                        )
                        if not inside:
                            continue
            if gate is not None and not gate.admits(index, beam.y if horizontal else beam.x, offset, inside):
                continue
            (dxs if horizontal else dys).append(offset)
    return (_median(dxs) if dxs else None), (_median(dys) if dys else None)
