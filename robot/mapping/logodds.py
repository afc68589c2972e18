"""The probabilistic mapper: log-odds evidence on a fine grid with an inverse sonar model.

Starts from Moravec & Elfes (1985) and Thrun (Probabilistic Robotics ch. 9), adapted to what sonar
gets wrong:
- the cone before an echo is free, with weight falling off towards the cone's edge and with range,
  where specular misses hide glancing surfaces; nothing behind a cell already believed occupied is
  cleared, since sound does not pass through it, and at the end every sweep's cones are cleared
  again behind what the whole run shows occupied (a reading that ran on through a surface before
  any echo had shown it cleared the floor inside the obstacle);
- an echo says the nearest surface is "somewhere on the arc". Its occupied evidence is shared out
  over the arc's cells in proportion to how likely each still is to hold that surface, and the
  sharing is recomputed from all the free evidence gathered since, so an arc recorded early is
  re-attributed once later views show which of its cells are free (Moravec & Elfes' "discounted by
  the empty evidence", applied to the whole history instead of the moment of the reading);
- a no-echo reading clears only a short stretch, weakly, since it is often a specular miss;
- the robot's body clears the cells under it.
Evidence lives on a fine grid (a few centimetres); a map cell is black if any fine cell in it is
occupied and white only if all of it is free, which keeps white cells safe.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from robot.config import RobotConfig
from robot.grid import FREE, OCCUPIED, UNKNOWN, GridSpec, dilate8
from robot.mapping.base import Evidence, MapFrame, blocked_by_extent
from robot.mapping.geometry import Beam, ConeCells, Cones, cones, place_beams
from robot.mapping.tangents import Line, TangentLines, TangentParams, box_walls, meet_at_corners
from robot.world import Pose


class LogOddsParams(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    fine_cell_m: float = Field(default=0.05, gt=0.005, le=0.5)  # evidence grid cell [m]
    l_free: float = Field(default=-0.7, lt=0.0)  # per reading, on the axis, near
    l_occ: float = Field(default=0.6, gt=0.0)  # per echo, to its most likely arc cell
    l_body: float = Field(default=-3.0, lt=0.0)  # cells under the robot
    l_contact: float = Field(default=3.0, gt=0.0)  # a bump
    free_clamp: float = Field(default=-6.0, lt=0.0)  # free evidence saturates here
    occ_threshold: float = Field(default=0.8, gt=0.0)
    free_threshold: float = Field(default=-0.65, lt=0.0)
    free_margin_m: float = Field(default=0.012, ge=0.0)  # carve up to this short of the echo ...
    free_margin_frac: float = Field(default=0.01, ge=0.0)  # ... plus this share of the range
    carve_full_m: float = Field(default=0.8, gt=0.0)  # full free weight up to here ...
    carve_max_m: float = Field(default=2.0, gt=0.0)  # ... fading to zero here
    no_echo_carve_m: float = Field(default=0.0, ge=0.0)  # how far a no-echo reading clears ...
    no_echo_weight: float = Field(default=0.5, ge=0.0, le=1.0)  # ... and how strongly
    # ... but in a sweep that maps no echo at all, where the room's surveyed box lies beyond the
    # sonar's range across the whole cone, no wall of the room can have turned the ping away: a
    # no-echo reading there clears its first open_carve_m. Without it a robot that starts in a hall
    # more than the sonar's range from every wall hears nothing, none of its floor becomes free, and
    # the run ends at once with an empty map (a 14 x 11 m hall started in its middle: 20 steps,
    # F1 0.008). 0 turns this off.
    open_carve_m: float = Field(default=1.0, ge=0.0)
    max_echo_range_m: float = Field(default=2.0, gt=0.0)  # echoes beyond this are not mapped
    occ_full_m: float = Field(default=0.6, gt=0.0)  # full occupied weight up to here, then fading
    occ_far_weight: float = Field(default=0.3, ge=0.0, le=1.0)  # ... to this at max_echo_range_m
    extent_snap_m: float = Field(default=0.03, ge=0.0)  # echoes this close inside the room box are its wall ...
    # ... but behind a wall this far off its edge. Walls are found in steps of 0.1 degree, so the
    # default lies between two. 1.5 -> 0.95 over 85 worlds x 3 seeds: 5 runs up (generated polygons
    # with a wall 1.2 degrees off, +0.005 to +0.018), none down; 0.7 the same; 0.5, over the first 82
    # of those runs, lost ushape seed 2 0.011.
    face_slant_deg: float = Field(default=0.95, ge=0.0, le=45.0)
    # ... and in the final map only along an edge where a wall was found from echoes within
    # face_slant_deg and face_wall_m of it, or where face_min_touches echoes touched the edge within
    # face_touch_window_m: elsewhere a polygon meets its box at a vertex, and the face cells hold its
    # walls. 85 worlds x 3 seeds: mean F1 0.9802 -> 0.9807, 46 runs up (generated polygons by up to
    # 0.014), 1 down (-0.0015); 64 fresh rooms x 2 seeds 10 up, none down; at 0.1 m 8 up, 2 down
    # (tworooms -0.004). Without the touches rule 60 up, 5 down, among them room4 1.000 -> 0.991
    # (furniture along two of its edges hides their walls from the line search).
    face_needs_wall: bool = True
    face_wall_m: float = Field(default=0.05, ge=0.0)
    face_min_touches: int = Field(default=2, ge=0)
    # 0.1 -> 0.2 m (2026-12-06): a robot that passes a wall once touches it once a sweep, 20 cm
    # apart, and a window of 10 cm either side left gaps between the touches where the face cells
    # kept the wall's echoes (a notched 7 x 5 m room, seed 1: 0.774 -> 0.800 at 0.2 m, 0.857 ->
    # 0.893 at 0.1 m; tworooms at 0.1 m seed 1 +0.005). No other of 34 worlds x 3 settings and 96
    # generated rooms changed.
    face_touch_window_m: float = Field(default=0.2, ge=0.0)
    # ... not counting the stretches a curved or slanting wall touched (see TangentLines.flush_touches):
    # echoes from beside the stretch fall face_short_m or less short of the edge, within
    # face_short_reach_m of it, as many as face_short_ratio of the stretch's touches (0 counts all).
    # On flat walls 0-0.25 of them, near curves and vertices 0.85 or more. 87 + 128 + 17 runs (seed 0
    # and 1, generated and built-in rooms): 20 up (by up to 0.010), none down; the paper's six rooms
    # (5 seeds) 8 up (roundroom 0.918 -> 0.938), none down, Table I unchanged; at 0.1 m roundroom up.
    face_short_m: float = Field(default=0.1, ge=0.0)
    face_short_reach_m: float = Field(default=0.3, ge=0.0)
    face_short_ratio: float = Field(default=0.5, ge=0.0)
    free_edge_weight: float = Field(default=0.5, ge=0.0, le=1.0)  # free weight at the cone edge
    arc_edge_weight: float = Field(default=0.6, ge=0.0, le=1.0)  # occupied prior at the cone edge
    free_discount: float = Field(default=1.5, ge=0.0)  # arc share falls as exp(discount * free evidence)
    pad_m: float = Field(default=0.3, ge=0.0)  # evidence kept this far past the map's edge
    explain_rounds: int = Field(default=2, ge=0, le=10)  # explaining-away iterations
    explain_gain: float = Field(default=1.0, ge=0.0)  # share grows as exp(gain * support) ...
    explain_cap: float = Field(default=5.0, gt=0.0)  # ... up to this support
    recheck_within: float = Field(default=0.25, ge=0.0, le=1.0)  # off-axis share in which a beam clears past echoes
    recheck_below: float = Field(default=3.0, gt=0.0)  # ... and only cells with less evidence than this
    boundary_support: float = Field(default=5.0, ge=0.0)  # the room box's wall, as support for sharing
    reattribute_every: int = Field(default=10, ge=1)  # sweeps between re-sharing every echo
    aperture_m: float = Field(default=0.03, ge=0.0)  # beam width at the transducer
    free_inset_cells: float = Field(default=0.25, ge=0.0)  # a cleared cell lies this far inside the beam
    hit_depth_cells: float = Field(default=0.75, ge=0.0, le=3.0)  # the solid cell lies this far behind the echo
    # Share of a map cell seen free to call it white (at 0.2 m: 15 of its 16 evidence cells). A wall
    # that clips a cell's corner leaves the part behind it unseen, and the truth counts that cell as
    # blocked. 0.7 -> 0.9 over 3 seeds of 16 worlds: angled walls and round furniture gained (hexagon
    # +0.004, trapezoid +0.007, room4 +0.005; at 0.1 m hexagon +0.035, room4 +0.013), room2 lost 0.003
    # (0.006 at 0.1 m), the rest moved by less than 0.001; requiring all 16 cost large rooms 0.005-0.009.
    white_min_free: float = Field(default=0.9, gt=0.0, le=1.0)
    # ... and in the finished map (once ``finalize`` has run), a cell beside a black one needs this
    # share: the tip of a turned desk or an ellipse that pokes a few centimetres into the next cell
    # is not seen, as no beam reaches it without touching the obstacle, but the rest of that cell is.
    # The exported map then takes the cell as the obstacle's. 0.9 -> 1.0 (every evidence cell) at
    # 0.2 m, the paths unchanged: Table I room2 0.968 -> 0.974, room3 0.983 -> 0.985, room4 0.995
    # -> 0.994; 85 worlds x 3 seeds 0.9819 -> 0.9823 (55 runs up, 29 down); 64 fresh rooms x 2 seeds
    # 0.9821 -> 0.9826 (15 up, 5 down). At 0.1 m (4 evidence cells a map cell) 0.9 asks for all already.
    white_min_free_beside: float = Field(default=1.0, gt=0.0, le=1.0)
    # In the finished map, when a map cell is narrower than the robot (0.1 m), a free cell between two
    # occupied ones in a row or a column is occupied, unless the robot's body has been on it: a beam
    # that grazes a face and hears nothing clears one cell of an outline, and the floor then runs
    # into the obstacle. At 0.1 m, same runs: 21 built-in worlds x 2 seeds 0.9668 -> 0.9677 (18 up,
    # 9 down, openhall seed 0 -0.010); 64 generated rooms 0.9747 -> 0.9760 (45 up, 10 down); the 32
    # of --seed 32 0.9774 -> 0.9789 (18 up, 3 down); Table I room2 0.942 -> 0.940 over 5 seeds. At
    # 0.2 m (a cell wider than the robot, where a one-cell gap can be a way through) the rule, then
    # without the body's exception, lost: 0.9825 -> 0.9809 over 85 worlds x 3 seeds.
    fill_gaps: bool = True
    # At the end, clear every sweep's cones again, hidden behind what the whole run shows occupied
    # instead of what each sweep's moment did: a sonar whose echo off a surface is lost at a glancing
    # angle may hear a farther one (multipath), and before any echo has shown that surface its cone
    # clears the floor inside the obstacle (room2 at 0.1 m: the inside of a desk set at 30 degrees
    # went white). The 21 built-in worlds at 0.1 m (2 seeds): 0.9590 -> 0.9668, 34 runs up, 1 down
    # (-0.0006); 85 worlds x 3 seeds at 0.2 m: 0.9811 -> 0.9819, 53 up, 30 down; 64 fresh rooms of
    # --seed 31 (2 seeds): 0.9807 -> 0.9821, 17 up, 5 down. It costs a second pass over the sweeps'
    # cones when the run ends (0.4-0.6 ms a sweep).
    final_occlusion: bool = True
    # ... and in that pass a cell up to this far in front of a cell believed occupied (along the
    # beam, within the band that cell hides) is hidden too: a beam that meets a face at a slant may
    # hear nothing from it (a specular miss) and run on past it, and it cleared the strip in front
    # of the solid cells, which is where a slanted or curved face cuts into the next cell. 0.9 of
    # an evidence cell, so that a face on a cell boundary seen head-on keeps the cells in front of
    # it (one evidence cell, 5 cm, nearer). Only the finished map changes, not the paths. On the
    # maps kept just before each run ended: 85 worlds x 3 seeds 0.9828 -> 0.9834 (58 runs up, 22
    # down, at most -0.014); 64 fresh rooms x 2 seeds 0.9818 -> 0.9832 (38 up, 6 down); Table I
    # room2 0.974 -> 0.978, room3 0.985 -> 0.986; at 0.1 m room2 0.940 -> 0.94996. A whole evidence
    # cell (1.0) hid the cells in front of faces on cell boundaries: 85 worlds (seed 0) 0.9838 ->
    # 0.9833, openhall -0.043. 0.95 scored as 0.9 on the paper's rooms, 0.8 less than half of it.
    final_front_cells: float = Field(default=0.9, ge=0.0, le=2.0)
    # The final pass reuses each sweep's cones, kept from its integration while they fit in this
    # much memory (about 60 kB a sweep in a paper room, up to 300 kB in a hall; 0 keeps none);
    # sweeps past it have their cones worked out again. The map is the same either way.
    final_cache_mb: float = Field(default=64.0, ge=0.0)
    # A straight wall found inside the room (not the box's own) says where its face is, within a
    # centimetre: evidence cells whose centres lie between inner_face_clear_m and inner_face_band_m
    # in front of it, over the stretch the echoes touched, are its face (free, like the box's face
    # band), except where another wall's face meets it in a concave corner. Where a face lies on a
    # cell boundary, the fringes of the echo arcs off it (an arc curves towards the robot away from
    # where it touches) had marked the cell in front black, a column out. Only walls within
    # inner_face_max_deg of a grid axis: a slanted wall cuts the cells it crosses, and its sliver in
    # the next cell is truth. The final map only. Seed 0 and seed 1, band 0.06 m: the 24 built-in
    # worlds with 32 fresh furnished rooms (--seed 2024) at 0.2 m 0.9794 -> 0.9798 and 0.9820 ->
    # 0.9823 (10 runs up, 2 down: cornered, whose cabinet reaches 1 cm into a cell); with 32 fresh
    # mixed rooms at 0.1 m 0.9727 -> 0.9739 and 0.9755 -> 0.9759 (31 up, 1 down by 0.00002; a
    # generated 10 cm partition 0.911 -> 0.947). A clearance of 2 cm missed faces found 7 mm off.
    inner_face_clear_m: float = Field(default=0.015, ge=0.0)
    inner_face_band_m: float = Field(default=0.06, ge=0.0)
    inner_face_max_deg: float = Field(default=3.0, ge=0.0, le=45.0)
    tangents: TangentParams = TangentParams()  # straight walls from the lines echoes are tangent to


class _ArcStore:
    """Every echo's arc, flattened into growing arrays: per arc cell its slot (a compact number for
    each fine cell any arc has touched), prior and the echo's evidence; per echo its start offset and
    size."""

    def __init__(self, n_cells: int) -> None:
        self.slots = np.zeros(4096, dtype=np.int64)
        self.prior = np.zeros(4096)
        self.evidence = np.zeros(4096)  # the echo's occupied evidence, on each of its cells
        self.starts = np.zeros(512, dtype=np.int64)
        self.sizes = np.zeros(512, dtype=np.int64)
        self.n_cells = 0
        self.n_arcs = 0
        self._slot_of = np.full(n_cells, -1, dtype=np.int64)  # fine cell -> slot
        self._touched = np.zeros(1024, dtype=np.int64)  # slot -> fine cell
        self.n_touched = 0

    @property
    def touched(self) -> NDArray[np.int64]:
        """The fine cell of every slot."""
        return self._touched[: self.n_touched]

    def subset(self, first_arc: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """The slots that arcs ``first_arc..`` touch, in increasing order, and each of their cells'
        place among them (what np.unique with return_inverse gives, without a sort)."""
        slots = self.slots[self.starts[first_arc] : self.n_cells]
        seen = np.zeros(self.n_touched, dtype=bool)
        seen[slots] = True
        space = np.flatnonzero(seen)
        place = np.empty(self.n_touched, dtype=np.int64)
        place[space] = np.arange(space.size)
        return space, place[slots]

    def add(
        self, cells: NDArray[np.int64], prior: NDArray[np.float64], sizes: list[int], evidence: list[float]
    ) -> None:
        """Append arcs: ``cells`` and ``prior`` hold them end to end, ``sizes`` and ``evidence`` one
        entry per arc. New cells get slots in increasing cell order (which slot a cell gets changes
        no number: every sum over a slot runs over its arc cells in their order)."""
        new = np.unique(cells[self._slot_of[cells] < 0])
        if new.size:
            if self.n_touched + new.size > self._touched.size:
                self._touched = np.resize(self._touched, max(2 * self._touched.size, self.n_touched + new.size))
            self._slot_of[new] = np.arange(self.n_touched, self.n_touched + new.size)
            self._touched[self.n_touched : self.n_touched + new.size] = new
            self.n_touched += new.size
        n, m = cells.size, len(sizes)
        if self.n_cells + n > self.slots.size:
            size = max(2 * self.slots.size, self.n_cells + n)
            self.slots = np.resize(self.slots, size)
            self.prior = np.resize(self.prior, size)
            self.evidence = np.resize(self.evidence, size)
        if self.n_arcs + m > self.starts.size:
            size = max(2 * self.starts.size, self.n_arcs + m)
            self.starts = np.resize(self.starts, size)
            self.sizes = np.resize(self.sizes, size)
        self.slots[self.n_cells : self.n_cells + n] = self._slot_of[cells]
        self.prior[self.n_cells : self.n_cells + n] = prior
        self.evidence[self.n_cells : self.n_cells + n] = np.repeat(evidence, sizes)
        offsets = itertools.accumulate(sizes[:-1], initial=self.n_cells)
        self.starts[self.n_arcs : self.n_arcs + m] = list(offsets)
        self.sizes[self.n_arcs : self.n_arcs + m] = sizes
        self.n_cells += n
        self.n_arcs += m


class _SweepCones(NamedTuple):
    beams: list[Beam]
    found: Cones
    sizes: NDArray[np.int64]
    ang: NDArray[np.float64]  # each cone cell's off-axis angle, as a share of the half-width, squared
    free_to: list[float]  # each beam clears up to this range [m]
    mapped: list[bool]  # each beam has an echo placed on the map


FINAL_BATCH_SWEEPS = 32  # sweeps cleared together in the final pass


def _cones_bytes(sweep: _SweepCones) -> int:
    c = sweep.found.cells
    arrays = (c.rows, c.cols, c.dist_m, c.off_axis_rad, c.inset_m, sweep.ang, sweep.sizes, sweep.found.starts)
    return sum(a.nbytes for a in arrays)


def _joined(sweeps: list[_SweepCones]) -> _SweepCones:
    """Several sweeps' cones as one sweep's, beam after beam."""
    if len(sweeps) == 1:
        return sweeps[0]
    cells = [s.found.cells for s in sweeps]
    offsets = np.cumsum([0] + [s.found.starts[-1] for s in sweeps[:-1]])
    later = [s.found.starts[1:] + o for s, o in zip(sweeps, offsets, strict=True)]
    starts = np.concatenate([sweeps[0].found.starts[:1], *later])
    found = Cones(
        ConeCells(
            rows=np.concatenate([c.rows for c in cells]),
            cols=np.concatenate([c.cols for c in cells]),
            dist_m=np.concatenate([c.dist_m for c in cells]),
            off_axis_rad=np.concatenate([c.off_axis_rad for c in cells]),
            inset_m=np.concatenate([c.inset_m for c in cells]),
        ),
        starts,
    )
    return _SweepCones(
        [b for s in sweeps for b in s.beams],
        found,
        np.concatenate([s.sizes for s in sweeps]),
        np.concatenate([s.ang for s in sweeps]),
        [f for s in sweeps for f in s.free_to],
        [m for s in sweeps for m in s.mapped],
    )


class LogOddsMapper:
    name = "logodds"

    def __init__(self, frame: MapFrame, robot: RobotConfig, params: LogOddsParams | None = None) -> None:
        self.frame = frame
        self.robot = robot
        self.params = p = params or LogOddsParams()
        grid = frame.grid
        self.k = max(1, round(grid.resolution / p.fine_cell_m))
        f = grid.resolution / self.k
        # The evidence grid extends past the map, so an echo off a wall on the map's edge has cells to
        # land in and does not get pinned on the free cells in front of the wall.
        self.pad = max(1, math.ceil(p.pad_m / f))
        pad = self.pad
        self.fine = GridSpec(
            grid.origin_x - pad * f,
            grid.origin_y - pad * f,
            f,
            grid.rows * self.k + 2 * pad,
            grid.cols * self.k + 2 * pad,
        )
        self._inner = (slice(pad, pad + grid.rows * self.k), slice(pad, pad + grid.cols * self.k))
        self.free_evidence = np.zeros(self.fine.shape, dtype=np.float32)  # <= 0
        self._body_free = np.zeros(self.fine.shape, dtype=np.float32)  # the body marks' part of it, unclamped
        # Every sweep, with final_occlusion: its cones while they fit in final_cache_mb, else its
        # pose and ranges to work them out again.
        self._kept: list[_SweepCones | tuple[Pose, NDArray[np.float64]]] = []
        self._kept_bytes = 0
        self._finalized = False  # finalize() has run: the export rules apply
        self.contact_evidence = np.zeros(self.fine.shape, dtype=np.float32)  # >= 0
        self._arcs = _ArcStore(self.fine.rows * self.fine.cols)
        self._support: NDArray[np.float64] | None = None  # per slot, from the last full re-sharing
        self._support_arcs = 0  # arcs covered by it
        # The echoes since, shared: the slots they touch (sorted) and the evidence on each.
        self._recent: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None
        self._occ_base: NDArray[np.float32] | None = None  # bumps plus the last full sharing
        self._sweeps_since_full = 0
        self._occ_cache: NDArray[np.float32] | None = None
        self._logodds_cache: NDArray[np.float32] | None = None
        self._fine_cache: NDArray[np.int8] | None = None
        self._counts_cache: NDArray[np.uint8] | NDArray[np.int32] | None = None
        self._half = math.radians(robot.sonar.beam_width_deg) / 2.0
        self._tangents = TangentLines(self._half, p.tangents) if p.tangents.enabled else None
        self._cut = np.zeros(grid.shape, dtype=bool)  # map cells a straight wall cuts through
        self._body = np.zeros(self.fine.shape, dtype=bool)  # evidence cells the body has been on
        # Evidence cell centres: x per column, y per row (GridSpec.index_to_world).
        self._centre_x = self.fine.index_to_world(0, np.arange(self.fine.cols))[0]
        self._centre_y = self.fine.index_to_world(np.arange(self.fine.rows), 0)[1]
        self._outside = blocked_by_extent(frame)
        # Evidence cells reaching past the surveyed room box (the padding included): its wall is there.
        self._beyond_box = np.zeros(self.fine.rows * self.fine.cols, dtype=bool)
        if frame.extent is not None:
            xs, ys = self.fine.centers()
            min_x, min_y, max_x, max_y = frame.extent
            h = 0.5 * f - 1e-9 * f  # a cell that only touches the box's edge is inside it
            beyond = (xs - h < min_x) | (xs + h > max_x) | (ys - h < min_y) | (ys + h > max_y)
            self._beyond_box = beyond.ravel()
            self._fine_outside = self._fine_outside_extent(frame.extent, 0.0)
            self._near_extent = self._fine_outside_extent(frame.extent, p.extent_snap_m)
        else:
            self._fine_outside = np.zeros((grid.rows * self.k, grid.cols * self.k), dtype=bool)
            self._near_extent = self._fine_outside
        # The few centimetres inside the room's surveyed box are the face of its outer wall: echoes
        # there come from the wall, and the floor up to it is free (see ``finalize`` for the
        # exception).
        self._face_band = self._near_extent & ~self._fine_outside
        self._wall_face = self._face_band

    def _fine_outside_extent(self, extent: tuple[float, float, float, float], margin_m: float) -> NDArray[np.bool_]:
        """Fine cells of the map's area whose centre lies outside the room box shrunk by ``margin_m``."""
        xs, ys = self.fine.centers()
        xs, ys = xs[self._inner], ys[self._inner]
        min_x, min_y, max_x, max_y = extent
        m = margin_m
        return (xs < min_x + m) | (xs > max_x - m) | (ys < min_y + m) | (ys > max_y - m)

    # -- evidence ----------------------------------------------------------------------------
    def _sweep_cones(self, pose: Pose, ranges_m: NDArray[np.float64]) -> _SweepCones:
        """A sweep's beams and their cones, with how far each clears and reaches."""
        p = self.params
        res = self.fine.resolution
        beams = place_beams(pose, ranges_m, self.robot)
        free_to, reach, mapped = [], [], []
        # A sweep without an echo it maps: nothing stands within that range in any direction (with
        # beams 45 degrees apart, a face near the robot turns towards one of them).
        quiet = p.open_carve_m > p.no_echo_carve_m and not any(
            b.echo and b.range_m <= p.max_echo_range_m for b in beams
        )
        for beam in beams:
            r = beam.range_m
            if beam.echo and r <= p.max_echo_range_m:
                free_to.append(r - p.free_margin_m - p.free_margin_frac * r)
                reach.append(r + (p.hit_depth_cells + 0.5) * res)
            elif beam.echo:
                # A far echo still clears the cone before it (the free weight fades out with range),
                # but its arc is too wide and too noisy to place a surface.
                free_to.append(min(r - p.free_margin_m - p.free_margin_frac * r, p.carve_max_m))
                reach.append(free_to[-1])
            else:
                carve = p.no_echo_carve_m
                if quiet and self._box_out_of_range(beam):
                    carve = p.open_carve_m
                free_to.append(min(carve, r))
                reach.append(free_to[-1])
            mapped.append(beam.echo and r <= p.max_echo_range_m)
        found = cones(self.fine, beams, self._half, reach, p.aperture_m)
        sizes = np.diff(found.starts)
        ang = (found.cells.off_axis_rad / self._half) ** 2
        return _SweepCones(beams, found, sizes, ang, free_to, mapped)

    def _box_out_of_range(self, beam: Beam) -> bool:
        """Whether every wall of the room's surveyed box lies farther than the sonar's range from the
        transducer, anywhere across the beam's cone (False when the room's size is unknown)."""
        extent = self.frame.extent
        if extent is None:
            return False
        min_x, min_y, max_x, max_y = extent
        reach = self.robot.sonar.max_range_m
        # Each box wall's distance d along its outward normal (at angle phi); along a direction off
        # the normal by delta the wall is d / cos(delta) away, nearest where delta is smallest.
        for d, phi in (
            (max_x - beam.x, 0.0),
            (beam.y - min_y, -0.5 * math.pi),
            (beam.x - min_x, math.pi),
            (max_y - beam.y, 0.5 * math.pi),
        ):
            if d >= reach:
                continue
            delta = abs(math.remainder(phi - beam.axis_rad, 2.0 * math.pi))
            delta = max(delta - self._half, 0.0)
            if delta < 0.5 * math.pi and d < reach * math.cos(delta):
                return False
        return True

    def _clear(self, sweep: _SweepCones, L: NDArray[np.float32], F: NDArray[np.float32], front_m: float = 0.0) -> None:
        """Add the free evidence of ``sweep``'s cones to ``F``, where belief ``L`` does not hide them
        (nor the cells up to ``front_m`` in front of what it holds occupied)."""
        p = self.params
        cells, sizes, ang, beams = sweep.found.cells, sweep.sizes, sweep.ang, sweep.beams
        # Clear only cells lying wholly inside the beam: a cell whose centre is inside but whose
        # corner pokes out may hold a chair leg the echo never saw.
        limit = np.repeat(np.asarray(sweep.free_to), sizes)
        free = (cells.dist_m < limit) & (cells.inset_m >= p.free_inset_cells * self.fine.resolution)
        self._clear_occluded(sweep.found, L, limit, free, front_m)
        cleared = np.flatnonzero(free)
        if cleared.size:
            d = cells.dist_m[cleared]
            # np.clip's arithmetic (max, then min) without its overhead.
            fall = np.minimum(np.maximum((p.carve_max_m - d) / max(p.carve_max_m - p.carve_full_m, 1e-9), 0.0), 1.0)
            w = (1.0 - (1.0 - p.free_edge_weight) * ang[cleared]) * fall
            weight = p.l_free * w
            if not all(beam.echo for beam in beams):  # (when all echo, every factor would be 1)
                weight = weight * np.repeat([1.0 if b.echo else p.no_echo_weight for b in beams], sizes)[cleared]
            # ufunc.at on flat indices (its fast path) adds repeats in order, as on (row, col) pairs.
            flat_f = F.reshape(-1)
            index = cells.rows[cleared] * self.fine.cols + cells.cols[cleared]
            np.add.at(flat_f, index, weight.astype(np.float32))
            flat_f[index] = np.maximum(flat_f[index], p.free_clamp)

    def integrate(self, pose: Pose, ranges_m: NDArray[np.float64]) -> None:
        p = self.params
        res = self.fine.resolution
        sweep = self._sweep_cones(pose, ranges_m)
        if p.final_occlusion:
            size = _cones_bytes(sweep)
            if self._kept_bytes + size <= p.final_cache_mb * 1e6:
                self._kept.append(sweep)
                self._kept_bytes += size
            else:
                self._kept.append((pose, np.array(ranges_m, dtype=np.float64)))
        self._clear(sweep, self.logodds, self.free_evidence)  # occluded by the belief before this sweep
        beams, found, sizes, ang, mapped = sweep.beams, sweep.found, sweep.sizes, sweep.ang, sweep.mapped
        cells = found.cells
        # The surface is at r; the occupied cell is the one just behind it: each mapped echo's arc
        # is its cone's cells at that distance, plus the cell on its axis.
        depth = p.hit_depth_cells * res
        f = self.fine
        span = max(p.max_echo_range_m - p.occ_full_m, 1e-9)
        near_edge = [b.range_m + depth - 0.5 * res if m else math.inf for b, m in zip(beams, mapped, strict=True)]
        far_edge = [b.range_m + depth + 0.5 * res if m else -math.inf for b, m in zip(beams, mapped, strict=True)]
        on_arc = np.flatnonzero(
            (cells.dist_m >= np.repeat(near_edge, sizes)) & (cells.dist_m < np.repeat(far_edge, sizes))
        )
        arc_index = cells.rows[on_arc] * f.cols + cells.cols[on_arc]
        arc_prior = 1.0 - (1.0 - p.arc_edge_weight) * ang[on_arc]
        bounds = np.searchsorted(on_arc, found.starts).tolist()
        # Beams without a mapped echo have no arc cells, so the arcs lie end to end in arc_index;
        # each gets its axis cell after its own cells.
        cone_starts = found.starts.tolist()
        axis_at, axis_cells, arc_sizes, strength = [], [], [], []
        for i, beam in enumerate(beams):
            if not mapped[i] or cone_starts[i] == cone_starts[i + 1]:
                continue  # no echo to map, or no cone cells at all
            r = beam.range_m
            size = bounds[i + 1] - bounds[i]
            ar, ac = f.point_index(
                beam.x + (r + depth) * math.cos(beam.axis_rad), beam.y + (r + depth) * math.sin(beam.axis_rad)
            )
            if 0 <= ar < f.rows and 0 <= ac < f.cols:
                axis_at.append(bounds[i + 1])
                axis_cells.append(ar * f.cols + ac)
                size += 1
            if size:
                near = min(max((p.max_echo_range_m - r) / span, 0.0), 1.0)
                arc_sizes.append(size)
                strength.append(p.l_occ * (p.occ_far_weight + (1.0 - p.occ_far_weight) * near))
        if self._tangents is not None:
            echoes = [b for b, m in zip(beams, mapped, strict=True) if m]
            self._tangents.add(
                [b.x for b in echoes], [b.y for b in echoes], [b.axis_rad for b in echoes], [b.range_m for b in echoes]
            )
        if arc_sizes:
            if axis_at:  # np.insert's result, without its overhead
                at = np.array(axis_at) + np.arange(len(axis_at))  # where the axis cells land
                arc = np.ones(arc_index.size + len(axis_at), dtype=bool)
                arc[at] = False
                index, prior = np.empty(arc.size, dtype=np.int64), np.empty(arc.size)
                index[arc], index[at] = arc_index, axis_cells
                prior[arc], prior[at] = arc_prior, 1.0
                arc_index, arc_prior = index, prior
            self._arcs.add(arc_index, arc_prior, arc_sizes, strength)
        self._sweeps_since_full += 1
        self._update_support(full=False)

    def _attribute(
        self,
        first_arc: int,
        support: NDArray[np.float64] | None,
        rounds: int,
        subset: tuple[NDArray[np.int64], NDArray[np.int64]] | None = None,
    ) -> NDArray[np.float64]:
        """Share the evidence of arcs ``first_arc..`` over their cells, on top of ``support`` (none: zero).

        Works per slot (see ``_ArcStore``), so the cost follows the arcs, not the size of the map:
        over every slot when ``subset`` is None, else over the slots it lists (sorted, holding all of
        the arcs' slots) with each arc cell's place among them. Returns the evidence per slot of
        that subset."""
        arcs = self._arcs
        lo = int(arcs.starts[first_arc])
        hi = arcs.n_cells
        slots = arcs.slots[lo:hi]
        touched = arcs.touched
        space = None
        if subset is not None:  # slots numbered within the subset
            space, slots = subset
            touched = touched[space]
        n = touched.size
        starts = arcs.starts[first_arc : arcs.n_arcs] - lo
        sizes = arcs.sizes[first_arc : arcs.n_arcs]
        strength = arcs.evidence[lo:hi]
        free = self.free_evidence.reshape(-1)[touched]
        # Every term that depends on the slot alone is computed once per slot, then gathered.
        base = arcs.prior[lo:hi] * np.exp(self.params.free_discount * free)[slots]
        before = np.zeros(n)
        if support is not None:
            if space is None:
                before[: support.size] = support
            else:
                known = int(np.searchsorted(space, support.size))  # the slots the last full sharing saw
                before[:known] = support[space[:known]]
        # An echo whose arc reaches the room's wall is most likely the wall: the cells beyond the box
        # count as supported, which explains away the arc's cells in the room.
        before += self.params.boundary_support * self._beyond_box[touched]
        own: NDArray[np.float64] = np.zeros(n)
        gain, cap = self.params.explain_gain, self.params.explain_cap
        for k in range(rounds + 1):
            # The first round has nothing of its own to add; a gain of 1 needs no multiplication.
            e = np.minimum(before + own if k else before, cap)
            w = base * np.exp(gain * e if gain != 1.0 else e)[slots]
            wmax = np.repeat(np.maximum(np.maximum.reduceat(w, starts), 1e-12), sizes)
            own = np.bincount(slots, weights=strength * w / wmax, minlength=n).astype(np.float64, copy=False)
        return own

    def _update_support(self, full: bool) -> None:
        """Share the echoes' evidence: all of them every ``reattribute_every`` sweeps (or when
        ``full``), otherwise only the new ones on top of the last full sharing.

        This runs at fixed points (the end of each sweep, and ``finalize``), never on a read, so the
        map does not depend on when anyone looks at it.
        """
        arcs = self._arcs
        p = self.params
        self._changed()
        if not arcs.n_arcs:
            return
        if full or self._support is None or self._sweeps_since_full >= p.reattribute_every:
            self._support = self._attribute(0, None, p.explain_rounds)
            self._support_arcs = arcs.n_arcs
            self._sweeps_since_full = 0
            self._recent = None
            self._occ_base = None
        elif arcs.n_arcs > self._support_arcs:
            # Only the slots of the new arcs: a few hundred cells, against thousands ever touched.
            space = arcs.subset(self._support_arcs)
            self._recent = (space[0], self._attribute(self._support_arcs, self._support, p.explain_rounds, space))
        self._changed()

    def _changed(self, occupied: bool = True) -> None:
        """The evidence changed: drop what was derived from it (the occupied share too if ``occupied``)."""
        if occupied:
            self._occ_cache = None
        self._logodds_cache = None
        self._fine_cache = None
        self._counts_cache = None

    def occupied_evidence(self) -> NDArray[np.float32]:
        """Every echo's evidence, shared over its arc by the free evidence gathered so far.

        Explaining away: an echo comes from the nearest surface, one place on its arc, so cells that
        other echoes already put a surface in take the larger share.
        """
        if self._occ_cache is None:
            contact = self.contact_evidence.reshape(-1)
            if self._occ_base is None:  # bumps and the last full sharing
                self._occ_base = self.contact_evidence.copy()
                if self._support is not None:
                    cells = self._arcs.touched[: self._support.size]
                    self._occ_base.reshape(-1)[cells] = contact[cells] + self._support.astype(np.float32)
            occ = self._occ_base.copy()
            if self._recent is not None and self._support is not None:  # the echoes since, on their cells
                space, recent = self._recent
                nonzero = np.flatnonzero(recent)
                slots, total = space[nonzero], recent[nonzero]
                total[slots < self._support.size] += self._support[slots[slots < self._support.size]]
                cells = self._arcs.touched[slots]
                occ.reshape(-1)[cells] = contact[cells] + total.astype(np.float32)
            self._occ_cache = occ
        return self._occ_cache

    @property
    def logodds(self) -> NDArray[np.float32]:
        """Free plus occupied evidence, read-only; computed once between changes (the engine reads it
        for the box fix and again for occlusion in the same sweep)."""
        if self._logodds_cache is None:
            L = self.free_evidence + self.occupied_evidence()
            L.flags.writeable = False
            self._logodds_cache = L
        return self._logodds_cache

    def _clear_occluded(
        self,
        found: Cones,
        L: NDArray[np.float32],
        limit: NDArray[np.float64],
        free: NDArray[np.bool_],
        front_m: float = 0.0,
    ) -> None:
        """Unmark in ``free`` the cone cells at or behind a cell already believed occupied, or up to
        ``front_m`` in front of it.

        A sonar cannot see through a solid object, so a reading that runs past a known obstacle in
        its cone (it missed it at a glancing angle, or the obstacle is off to the side) says nothing
        about the space behind it.
        """
        cells = found.cells
        believed = L[cells.rows, cells.cols]
        hits = np.flatnonzero((believed >= self.params.occ_threshold) & (cells.dist_m < limit + front_m))
        if not hits.size:
            return
        starts = found.starts.tolist()
        first_hit = np.searchsorted(hits, found.starts).tolist()  # each beam's hits: first_hit[i]:first_hit[i + 1]
        res = self.fine.resolution
        for i in range(len(starts) - 1):
            if first_hit[i] == first_hit[i + 1]:
                continue
            lo, hi = starts[i], starts[i + 1]
            rows = np.flatnonzero(free[lo:hi])  # only cells still to be cleared need the test
            if not rows.size:
                continue
            dist, off = cells.dist_m[lo:hi], cells.off_axis_rad[lo:hi]
            hit = hits[first_hit[i] : first_hit[i + 1]] - lo
            occ_d, occ_a = dist[hit], off[hit]
            half_width = np.arctan2(0.75 * res, occ_d)  # angular half-size of a cell
            d, a = dist[rows], off[rows]
            behind = (d[:, None] >= occ_d[None, :] - front_m - 1e-9) & (
                np.abs(a[:, None] - occ_a[None, :]) <= half_width[None, :]
            )
            # A cell believed occupied does not hide itself from a beam that runs on past it near the
            # beam's axis: that is how a wrongly placed echo gets cleared again.
            central = np.abs(occ_a) <= self.params.recheck_within * self._half
            central &= believed[lo:hi][hit] < self.params.recheck_below
            own = np.minimum(np.searchsorted(rows, hit), rows.size - 1)  # each hit's row among them
            central &= rows[own] == hit
            behind[own[central], np.flatnonzero(central)] = False
            free[lo + rows[np.any(behind, axis=1)]] = False

    def _disk(self, x: float, y: float, radius: float) -> tuple[slice, slice, NDArray[np.bool_]]:
        """The evidence cells whose centres lie within ``radius`` of (x, y): a box of them and a mask."""
        f = self.fine
        r0, c0 = f.point_index(x + radius, y + radius)
        r1, c1 = f.point_index(x - radius, y - radius)
        top, left = max(r0, 0), max(c1, 0)
        rows = slice(top, max(min(r1, f.rows - 1) + 1, top))  # never a negative (from the end) stop
        cols = slice(left, max(min(c0, f.cols - 1) + 1, left))
        cx, cy = self._centre_x[None, cols], self._centre_y[rows, None]
        return rows, cols, np.hypot(cx - x, cy - y) <= radius

    def mark_body(self, pose: Pose) -> None:
        rows, cols, disk = self._disk(pose.x, pose.y, self.robot.radius_m)
        F = self.free_evidence[rows, cols]
        F[disk] = np.maximum(F[disk] + self.params.l_body, self.params.free_clamp)
        if self.params.final_occlusion:
            self._body_free[rows, cols][disk] += self.params.l_body
        self._body[rows, cols] |= disk
        self._changed(occupied=False)

    def mark_contact(self, pose: Pose, direction_rad: float) -> None:
        d = self.robot.radius_m + 0.5 * self.fine.resolution
        r, c = self.fine.world_to_index(pose.x + d * math.cos(direction_rad), pose.y + d * math.sin(direction_rad))
        if self.fine.contains_index(r, c):
            self.contact_evidence[int(r), int(c)] += self.params.l_contact
            self._occ_base = None
            self._changed()

    def evidence(self) -> Evidence | None:
        return Evidence(self.fine, self.logodds)

    def finalize(self) -> None:
        self._finalized = True
        self._update_support(full=True)
        if self.params.final_occlusion and self._kept:
            # Clear every sweep's cones again, now hidden behind what the whole run shows occupied.
            L = self.logodds
            F = self._body_free.copy()
            front = self.params.final_front_cells * self.fine.resolution
            # A batch of sweeps at a time, cleared as one: the free weights are never positive, so
            # clamping once per batch gives what clamping after every sweep would.
            batch: list[_SweepCones] = []
            for kept in self._kept:
                batch.append(kept if isinstance(kept, _SweepCones) else self._sweep_cones(*kept))
                if len(batch) == FINAL_BATCH_SWEEPS:
                    self._clear(_joined(batch), L, F, front)
                    batch = []
            if batch:
                self._clear(_joined(batch), L, F, front)
            self._kept, self._kept_bytes = [], 0
            self.free_evidence = np.maximum(F, self.params.free_clamp)
            self._update_support(full=True)
        if self._tangents is not None:
            occupied = self.logodds >= self.params.occ_threshold
            walls = [w for w in self._tangents.lines() if self._tangents.on_evidence(w, self.fine, occupied)]
            extent = self.frame.extent
            box = box_walls(extent) if extent is not None and self._tangents.params.meet_box else []
            walls = meet_at_corners(walls, self._tangents.params, box)
            inside: list[Line] = []
            off_edge: list[Line] = []  # along a box edge but leaning off it (see ``box_lean_min_deg``)
            box_found: list[Line] = []  # the box's own
            for w in walls:
                if extent is None or not self._tangents.near_box(w, extent):
                    inside.append(w)
                elif self._tangents.leans(w):
                    off_edge.append(w)
                else:
                    box_found.append(w)
            self._cut = self._wall_cuts(self._tangents, inside)
            if off_edge:
                self._cut |= self._wall_cuts(self._tangents, off_edge, self._tangents.params.box_lean_margin_m)
            self._wall_face = self._face_band & ~self._past_slanting_walls(box_found)
            if self.params.face_needs_wall and extent is not None:
                self._wall_face &= self._faces_of_found_edges(self._tangents, extent, box_found)
            if self.params.inner_face_band_m > 0.0 and (inside or off_edge):
                self._wall_face = self._wall_face | self._in_front_of_walls(inside + off_edge, walls)
            self._changed(occupied=False)

    def _inner_centres(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The x of each column and the y of each row of the evidence cells over the map's area, as a
        row and a column (they broadcast to the cells' centres)."""
        rows, cols = self._inner
        return self._centre_x[None, cols], self._centre_y[rows, None]

    def _in_front_of_walls(self, walls: list[Line], others: list[Line]) -> NDArray[np.bool_]:
        """Evidence cells of the map's area whose centres lie between ``inner_face_clear_m`` and
        ``inner_face_band_m`` in front of one of ``walls`` over its touched stretch, and not on or
        past any of ``others`` (where two faces meet in a concave corner)."""
        p = self.params
        xs, ys = self._inner_centres()
        out = np.zeros(self._face_band.shape, dtype=bool)
        for wall in walls:
            if wall.off_axis_rad > math.radians(p.inner_face_max_deg):
                continue
            depth = wall.depth(xs, ys)
            along = wall.along_many(xs, ys)
            out |= (
                (depth <= -p.inner_face_clear_m)
                & (depth > -p.inner_face_band_m)
                & (along >= wall.s0)
                & (along <= wall.s1)
            )
        if out.any():
            for other in others:
                depth = other.depth(xs, ys)
                along = other.along_many(xs, ys)
                on = (depth > -p.inner_face_clear_m) & (depth <= self.fine.resolution)
                out &= ~(on & (along >= other.s0 - 0.05) & (along <= other.s1 + 0.05))
        return out & ~self._fine_outside

    def _faces_of_found_edges(
        self, tangents: TangentLines, extent: tuple[float, float, float, float], walls: list[Line]
    ) -> NDArray[np.bool_]:
        """Evidence cells of the map's area near a box edge (within ``extent_snap_m``) along which a
        wall was found from echoes (``walls``: within ``face_slant_deg`` and ``face_wall_m`` of the
        edge), or within ``face_touch_window_m`` of where ``face_min_touches`` echoes touched it
        (on a stretch that no curved or slanting wall touched, when ``face_short_ratio`` is set)."""
        p = self.params
        xs, ys = self._inner_centres()
        min_x, min_y, max_x, max_y = extent
        m = p.extent_snap_m
        bands = (xs > max_x - m, ys > max_y - m, xs < min_x + m, ys < min_y + m)  # box_walls' order
        out = np.zeros(self._face_band.shape, dtype=bool)
        slant = math.radians(p.face_slant_deg)
        for edge, band in zip(box_walls(extent), bands, strict=True):
            if any(w.near(edge, slant, p.face_wall_m) for w in walls):
                out |= band
            elif p.face_min_touches > 0:
                if p.face_short_ratio > 0.0:
                    touched = tangents.flush_touches(edge, p.face_short_m, p.face_short_reach_m, p.face_short_ratio)
                else:
                    touched = tangents.touches(edge)
                along = edge.along_many(xs, ys)
                first = np.searchsorted(touched, along - p.face_touch_window_m)
                count = np.searchsorted(touched, along + p.face_touch_window_m, side="right") - first
                out |= band & (count >= p.face_min_touches)
        return out

    def _past_slanting_walls(self, walls: list[Line]) -> NDArray[np.bool_]:
        """Evidence cells of the map's area that reach ``tangents.margin_m`` or more past a straight
        wall near the room box's edge that runs at least ``face_slant_deg`` off the edge, over the
        stretch the echoes touched it (extended to a corner).

        In a room that is not a box, such a wall meets the box edge at a vertex and runs a few
        centimetres inside it; the face cells behind it are not the outer wall's face, and are left
        to their own evidence. The walls of the box, found from echoes, run within a degree of it."""
        xs, ys = self._inner_centres()
        past = np.zeros(self._face_band.shape, dtype=bool)
        half = 0.5 * self.fine.resolution
        for wall in walls:
            if wall.off_axis_rad < math.radians(self.params.face_slant_deg):
                continue
            past |= wall.cells_past(xs, ys, half, self.params.tangents.margin_m)
        return past

    def _wall_cuts(self, tangents: TangentLines, walls: list[Line], margin_m: float | None = None) -> NDArray[np.bool_]:
        """Map cells that the straight walls the echoes agree on (``walls``, on the evidence and not
        the room box's own) cut into (``margin_m`` past them, by default the tangents' margin for the
        wall's angle), except where the robot's body has been on the far side of the wall (then it is
        not a wall there: a doorway, say)."""
        (xs, ys), body = self._inner_centres(), self._body[self._inner]
        cut = np.zeros(self.frame.grid.shape, dtype=bool)
        for wall in walls:
            cells = tangents.cut_cells(self.frame.grid, [wall], margin_m)
            if cells.any():
                past = body & (wall.depth(xs, ys) > 0.0)
                cut |= cells & ~(self._block_counts(past) > 0)
        return cut & ~self._outside

    # -- belief -------------------------------------------------------------------------------
    def fine_states(self) -> NDArray[np.int8]:
        """Per evidence cell over the map's area (padding excluded): FREE, OCCUPIED or UNKNOWN."""
        if self._fine_cache is not None:
            return self._fine_cache
        p = self.params
        L = self.logodds[self._inner]
        out = np.full(L.shape, UNKNOWN, dtype=np.int8)
        out[L >= p.occ_threshold] = OCCUPIED
        out[L <= p.free_threshold] = FREE
        out[self._wall_face] = FREE
        self._fine_cache = out
        return out

    def _block_counts(self, masks: NDArray[np.bool_]) -> NDArray[np.uint8] | NDArray[np.int32]:
        """Per map cell, how many of its k x k evidence cells each of ``masks`` (m, rows * k, cols * k)
        holds, (m, rows, cols), or one mask's (rows, cols): the k rows of each block added, then its k
        columns (slices added in bytes, while a block's count fits in one; cheaper than numpy's sum,
        which casts)."""
        if masks.ndim == 2:
            return self._block_counts(masks[None])[0]
        grid = self.frame.grid
        k = self.k
        cells = masks.view(np.uint8) if k * k <= 255 else masks.astype(np.int32)
        if k == 1:  # one evidence cell per map cell: the mask is the count
            return cells
        m = masks.shape[0]
        by_row = cells.reshape(m, grid.rows, k, grid.cols * k)
        rows = by_row[:, :, 0] + by_row[:, :, 1]
        for i in range(2, k):
            rows += by_row[:, :, i]
        by_col = rows.reshape(m, grid.rows, grid.cols, k)
        counts = by_col[..., 0] + by_col[..., 1]
        for i in range(2, k):
            counts += by_col[..., i]
        return counts

    def _cell_counts(self) -> NDArray[np.uint8] | NDArray[np.int32]:
        """Per map cell, its evidence cells that are occupied, occupied inside the room box, free,
        and free or outside the box (4, rows, cols): counted together, once per change. Occupied and
        free are what ``fine_states`` calls them (the thresholds lie either side of zero)."""
        if self._counts_cache is None:
            p = self.params
            L = self.logodds[self._inner]
            masks = np.empty((4, *L.shape), dtype=bool)
            occupied, occupied_inside, free, free_or_outside = masks
            np.greater_equal(L, p.occ_threshold, out=occupied)
            occupied &= ~self._wall_face
            np.logical_and(occupied, ~self._fine_outside, out=occupied_inside)
            np.less_equal(L, p.free_threshold, out=free)
            free |= self._wall_face
            np.logical_or(free, self._fine_outside, out=free_or_outside)
            self._counts_cache = self._block_counts(masks)
        return self._counts_cache

    def free_fraction(self) -> NDArray[np.float64]:
        counts = self._cell_counts()
        occ = (counts[0] > 0) | self._outside
        # A count over k * k is exactly what the mean of the block's booleans gives.
        return np.where(occ, -1.0, counts[2] / (self.k * self.k))

    def states(self) -> NDArray[np.int8]:
        grid = self.frame.grid
        counts = self._cell_counts()
        occ = counts[1] > 0
        # White needs no occupied evidence and nearly all of the cell seen free: a strip along an
        # obstacle's face that no beam could clear without touching the face may stay unseen.
        free_frac = counts[3] / (self.k * self.k)
        free = free_frac >= self.params.white_min_free
        if self._finalized and self.params.white_min_free_beside > self.params.white_min_free:
            beside = dilate8(occ | self._cut)
            free &= ~beside | (free_frac >= self.params.white_min_free_beside)
        out = np.full(grid.shape, UNKNOWN, dtype=np.int8)
        out[free & ~self._outside] = FREE
        out[occ | self._outside | self._cut] = OCCUPIED
        if self._finalized and self.params.fill_gaps and grid.resolution < 2.0 * self.robot.radius_m:
            out[self._gaps(out)] = OCCUPIED
        return out

    def _gaps(self, states: NDArray[np.int8]) -> NDArray[np.bool_]:
        """Free map cells between two occupied ones, across a row or a column, where the robot's body
        has not been."""
        occ = np.pad(states == OCCUPIED, 1)
        between = (occ[:-2, 1:-1] & occ[2:, 1:-1]) | (occ[1:-1, :-2] & occ[1:-1, 2:])
        body = self._block_counts(self._body[self._inner]) > 0
        return (states == FREE) & between & ~body
