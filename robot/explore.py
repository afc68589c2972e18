"""BOB-style exploration: one navigation cell per step, clockwise neighbour priority, backtracking.

The navigation grid is the map grid coarsened so that one navigation cell holds the robot and its
turning circle. A navigation cell is traversable when every map cell in it is believed free. When
the depth-first search runs out, the explorer plans (breadth-first, over known traversable cells) to
unvisited traversable cells, then to spots next to remaining frontier cells (unknown cells touching
the reachable free area), which it inspects a bounded number of times before accepting them as
blocked. When the map has settled while frontier cells remain (runs that end once mapped), it heads
for the nearest unvisited cell next to them, or else looks from the nearest visited one, instead of
walking on depth-first through explored floor.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Container, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robot.grid import UNKNOWN, GridSpec, dilate8
from robot.truth import reachable_cells

# Neighbour offsets (drow, dcol) clockwise from "north" (+y, which is row - 1).
CLOCKWISE = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))


def direction_index(theta_rad: float) -> int:
    """Index into CLOCKWISE of the 45-degree direction nearest to a heading."""
    # Heading 90 deg (north) -> 0, 45 deg (north-east) -> 1, 0 deg (east) -> 2, ...
    return int(round((math.pi / 2 - theta_rad) / (math.pi / 4))) % 8


def direction_heading(index: int) -> float:
    return math.atan2(math.sin(math.pi / 2 - index * math.pi / 4), math.cos(math.pi / 2 - index * math.pi / 4))


@dataclass
class Action:
    kind: str  # "move", "inspect", "unpin", "done"
    target: tuple[int, int] | None = None  # navigation cell to move to
    heading_rad: float | None = None  # for "inspect": face this way and sweep
    reason: str = ""  # "explore", "backtrack", "revisit", "frontier", or for done: terminated_by


@dataclass
class Explorer:
    grid: GridSpec  # the map grid
    block: int  # map cells per navigation cell side
    start_cell: tuple[int, int]  # navigation cell of the start
    max_inspections: int = 2
    min_free_fraction: float = 0.25  # share of a navigation cell seen free before driving into it
    visited: NDArray[np.bool_] = field(init=False)
    bumped: NDArray[np.bool_] = field(init=False)
    stack: list[tuple[int, int]] = field(default_factory=list)
    inspections: dict[tuple[int, int], int] = field(default_factory=dict)  # map cell -> count
    given_up: set[tuple[int, int]] = field(default_factory=set)
    max_escapes: int = 5  # times a robot boxed in by its own map may step again into a cell it escaped to
    escapes: int = 0
    escaped_to: set[tuple[int, int]] = field(default_factory=set)  # cells escape moves have headed for
    max_probes: int = 8  # drives into a cell the map holds occupied, to find a passage (see ``probe``)
    max_unpins: int = 0  # last-resort side steps before ending boxed in (see ``_plan``)
    unpins: int = 0
    probe_min_cells: int = 4  # ... to traversable floor beyond with at least this many navigation cells
    probe_free_fraction: float = 0.9  # ... seen free over this share
    probed: set[tuple[int, int]] = field(default_factory=set)
    # A beam within this of one of the 8 directions, from a navigation cell, looks along it ...
    view_tolerance_deg: float = 10.0
    # ... and sees through the next cell into unknown space when it hears no echo at all; one that
    # echoes within view_steps steps (from the robot's centre) does not see through it (see
    # ``note_view``). A cell is seen through when at least view_min_open beams did so and none did
    # not; with fewer, the robot first turns that way and looks again (once per cell and
    # direction). A sonar drops readings at random: one beam that heard nothing of a cabinet's face
    # in front of it sent the robot into the cabinet. Counting echoes from past the cell as seeing
    # through it sent robots into cabinets through a 25 cm strip beside their top (4 rooms of 32 down
    # by 0.004-0.020, none up).
    view_steps: float = 2.5
    view_min_open: int = 2
    looked: set[tuple[tuple[int, int], int]] = field(default_factory=set)
    # The look ``probe`` asks for before its probe: a navigation cell and a direction.
    pending_look: tuple[tuple[int, int], int] | None = field(default=None, init=False)
    _around_reach_cache: tuple[tuple[NDArray[np.bool_], tuple[int, int]], NDArray[np.bool_]] | None = field(
        default=None, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        self.nav_rows = -(-self.grid.rows // self.block)
        self.nav_cols = -(-self.grid.cols // self.block)
        self.visited = np.zeros((self.nav_rows, self.nav_cols), dtype=bool)
        self.bumped = np.zeros_like(self.visited)
        # Per navigation cell and direction (CLOCKWISE; the straight ones only), the beams from it that
        # saw through the next cell in that direction, and those that did not.
        self.views_open = np.zeros((self.nav_rows, self.nav_cols, 8), dtype=np.int32)
        self.views_shut = np.zeros_like(self.views_open)

    # -- geometry -------------------------------------------------------------------------------
    def nav_center(self, cell: tuple[int, int]) -> tuple[float, float]:
        """World (x, y) of a navigation cell's centre; its first map row is the top one."""
        g = self.grid
        b = self.block
        r, c = cell
        x = g.origin_x + (c * b + b / 2) * g.resolution
        top_y = g.origin_y + (g.rows - r * b) * g.resolution
        return x, top_y - b / 2 * g.resolution

    def nav_cell_of(self, x: float, y: float) -> tuple[int, int]:
        g = self.grid
        b = self.block
        col = math.floor((x - g.origin_x) / (g.resolution * b))
        row = math.floor((g.origin_y + g.rows * g.resolution - y) / (g.resolution * b))
        return int(row), int(col)

    def _nav_blocks(self, values: NDArray[Any], past_grid: float | bool) -> NDArray[Any]:
        """Per-map-cell ``values`` as blocks of navigation cells, (nav rows, block, nav cols, block),
        with ``past_grid`` where a navigation cell reaches past the grid."""
        b = self.block
        padded = np.full((self.nav_rows * b, self.nav_cols * b), past_grid, dtype=values.dtype)
        padded[: self.grid.rows, : self.grid.cols] = values
        return padded.reshape(self.nav_rows, b, self.nav_cols, b)

    def _map_cells(self, nav: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """The map cells of the navigation cells in ``nav``."""
        b = self.block
        full = np.repeat(np.repeat(nav, b, axis=0), b, axis=1)
        return full[: self.grid.rows, : self.grid.cols]

    def traversable(self, free_fraction: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Navigation cells with nothing occupied in them and at least a quarter seen free.

        ``free_fraction`` is per map cell, negative where the cell holds an obstacle; cells past the
        grid count as walls.
        """
        blocks = self._nav_blocks(free_fraction, -1.0)
        ok = (blocks.min(axis=(1, 3)) >= 0.0) & (blocks.mean(axis=(1, 3)) >= self.min_free_fraction)
        return ok & ~self.bumped

    def traversable_at(self, current: tuple[int, int], free_fraction: NDArray[np.float64]) -> NDArray[np.bool_]:
        """``traversable``, with the navigation cell the robot stands in counted in."""
        trav = self.traversable(free_fraction)
        trav[current] = True  # the robot is standing in it
        return trav

    def note_view(self, x: float, y: float, axes_rad: Iterable[float], reaches_m: Iterable[float]) -> None:
        """Record a sweep taken at (x, y): each beam's axis and how far from (x, y) its echo lies
        (``math.inf`` when it heard none). A beam within ``view_tolerance_deg`` of one of the 4
        straight directions (the only ones ``probe`` looks along) sees through the next cell that way
        when it heard no echo, and not when it heard one within ``view_steps`` steps."""
        cell = self.nav_cell_of(x, y)
        if not (0 <= cell[0] < self.nav_rows and 0 <= cell[1] < self.nav_cols):
            return
        tolerance = math.radians(self.view_tolerance_deg)
        step = self.block * self.grid.resolution
        for axis, reach in zip(axes_rad, reaches_m, strict=True):
            k = direction_index(axis)
            off = math.remainder(axis - direction_heading(k), math.tau)
            if k % 2 or abs(off) > tolerance:
                continue
            if math.isinf(reach):
                self.views_open[cell[0], cell[1], k] += 1
            elif reach < self.view_steps * step:
                self.views_shut[cell[0], cell[1], k] += 1

    def _sees_through(self, cell: tuple[int, int], k: int) -> bool | None:
        """Whether every beam from ``cell`` along direction ``k`` saw through the next cell, at least
        ``view_min_open`` of them; None when they all did but are fewer, and no look was taken yet."""
        open_, shut = self.views_open[cell[0], cell[1], k], self.views_shut[cell[0], cell[1], k]
        if open_ == 0 or shut > 0:
            return False
        if open_ >= self.view_min_open:
            return True
        return None if (cell, k) not in self.looked else False

    # -- decisions -------------------------------------------------------------------------------
    def _can_step(
        self, trav: NDArray[np.bool_], cell: tuple[int, int], d: tuple[int, int], relaxed: bool = False
    ) -> bool:
        r, c = cell[0] + d[0], cell[1] + d[1]
        if not (0 <= r < self.nav_rows and 0 <= c < self.nav_cols) or not trav[r, c]:
            return False
        if relaxed and self.visited[cell] and self.visited[r, c]:
            return True  # the robot has stood at both ends
        if d[0] != 0 and d[1] != 0:  # a diagonal needs both orthogonal neighbours clear
            return bool(trav[cell[0] + d[0], cell[1]] and trav[cell[0], cell[1] + d[1]])
        return True

    def frontier(
        self, states: NDArray[np.int8], passable: NDArray[np.bool_], doubtful: NDArray[np.bool_] | None = None
    ) -> NDArray[np.bool_]:
        """Unresolved map cells (neither free nor occupied) in or next to the area the robot can reach.

        ``doubtful`` marks occupied cells worth a closer look (an occupied cell between the reachable
        area and unknown space may be a false echo closing off a passage); they count as frontier too.
        """
        unresolved = states == UNKNOWN
        if doubtful is not None:
            unresolved = unresolved | doubtful
        front = unresolved & self._around_reach(passable | self._visited_map_cells())
        for cell in self.given_up:
            front[cell] = False
        return front

    def _around_reach(self, open_cells: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """Map cells in or next to the open cells reachable from the start. Kept for the last
        ``open_cells``: the engine asks after every step, and most steps open nothing new."""
        key = (open_cells, self._start_map_cell())
        cached = self._around_reach_cache
        # (Comparing bytes is np.array_equal for one shape and dtype, without its overhead.)
        if cached is None or cached[0][1] != key[1] or cached[0][0].tobytes() != open_cells.tobytes():
            cached = (key, dilate8(reachable_cells(~open_cells, *key[1])))
            self._around_reach_cache = cached
        return cached[1]

    def passages(self) -> NDArray[np.bool_]:
        """Map cells of the navigation cells the robot has probed (see ``probe``) and driven into."""
        through = np.zeros_like(self.visited)
        for cell in self.probed:
            through[cell] = self.visited[cell] and not self.bumped[cell]
        return self._map_cells(through)

    def _visited_map_cells(self) -> NDArray[np.bool_]:
        return self._map_cells(self.visited)

    def _start_map_cell(self) -> tuple[int, int]:
        b = self.block
        r = min(self.start_cell[0] * b + b // 2, self.grid.rows - 1)
        c = min(self.start_cell[1] * b + b // 2, self.grid.cols - 1)
        return r, c

    def decide(
        self,
        current: tuple[int, int],
        heading_rad: float,
        states: NDArray[np.int8],
        passable: NDArray[np.bool_],
        free_fraction: NDArray[np.float64],
        doubtful: NDArray[np.bool_] | None = None,
        seek_frontier: bool = False,
        give_up_closed: bool = False,
        probe_cells: NDArray[np.bool_] | None = None,
    ) -> Action:
        """The next action from navigation cell ``current`` facing ``heading_rad``.

        ``seek_frontier`` (the map has settled while unresolved cells remain): head for the nearest
        unvisited cell next to the frontier, or else look from the nearest visited one, instead of
        walking on depth-first through explored floor. ``give_up_closed`` as well (the map has been
        settled for longer): when no cell beside the frontier can be reached, give the frontier up.
        ``probe_cells``: occupied map cells that only echoes say are occupied (see ``probe``).
        """
        self.visited[current] = True
        trav = self.traversable_at(current, free_fraction)
        if seek_frontier:
            front = self.frontier(states, passable, doubtful)
            if front.any():
                # Cells not stood in yet first (a walk along the frontier sees more than a look from
                # one spot), then a look from where the robot has been, as at the walk's end.
                for spots_in in (trav & ~self.visited, self.visited):
                    action, reached = self._search(current, trav, front, relaxed=False, seek_in=spots_in)
                    if action is not None:
                        return action
                # No cell beside them can be reached, though the robot can still get back to most of
                # where it has been: the map has closed them off (the inside of furniture seen
                # through a gap narrower than the robot, or cells behind one it stood in before it
                # was found occupied). Walking on may still open a view of them, but not for ever.
                if give_up_closed and not self._cut_off(reached):
                    self.given_up.update(zip(*np.nonzero(front), strict=True))
            # A gap the sonar arcs closed is left to resolve too: head for it now rather than after
            # walking the rest of the room depth-first. (Not one only the beams saw through: that
            # waits until nothing else is left, so that it changes no path before then.)
            probing = self._probe_action(current, trav, free_fraction, probe_cells, see_through=False)
            if probing is not None:
                return probing
        first = direction_index(heading_rad)
        for k in range(8):
            d = CLOCKWISE[(first + k) % 8]
            nxt = (current[0] + d[0], current[1] + d[1])
            if self._can_step(trav, current, d) and not self.visited[nxt]:
                self.stack.append(current)
                return Action("move", nxt, reason="explore")
        while self.stack:
            prev = self.stack.pop()
            if prev != current and max(abs(prev[0] - current[0]), abs(prev[1] - current[1])) == 1:
                d = (prev[0] - current[0], prev[1] - current[1])
                if self._can_step(trav, current, d):
                    return Action("move", prev, reason="backtrack")
            elif prev == current:
                continue
            # The stack entry is no longer adjacent (after a detour): plan a path to it instead.
            self.stack.append(prev)
            break
        return self._plan(current, trav, states, passable, free_fraction, doubtful, probe_cells)

    def _plan(
        self,
        current: tuple[int, int],
        trav: NDArray[np.bool_],
        states: NDArray[np.int8],
        passable: NDArray[np.bool_],
        free_fraction: NDArray[np.float64],
        doubtful: NDArray[np.bool_] | None = None,
        probe_cells: NDArray[np.bool_] | None = None,
    ) -> Action:
        """Breadth-first search over traversable cells for the nearest useful goal."""
        front = self.frontier(states, passable, doubtful)
        action, reached = self._search(current, trav, front, relaxed=False)
        if action is None and self.escapes < self.max_escapes and self._cut_off(reached):
            # Cut off from most of where it has been: the map (a wall clipping the cells around, a
            # bump) closes every way out. Cells the robot has stood in, and the straight moves
            # between them, were passable once; retry them rather than end the run with the room
            # half explored.
            # A step into a cell not escaped to before does not count against the budget: a robot
            # backing out of a long slot that the map has since closed steps through new cells, while
            # one that keeps bumping, or goes round in a loop, steps into the same ones again.
            action, _ = self._search(current, trav | self.visited, front, relaxed=True)
            if action is not None:
                if action.target is None or action.target in self.escaped_to:
                    self.escapes += 1
                else:
                    self.escaped_to.add(action.target)
        if action is not None:
            return action
        probing = self._probe_action(current, trav, free_fraction, probe_cells)
        if probing is not None:
            return probing
        # Nothing reachable is left to do: frontier cells nobody can get next to are given up. When the
        # robot cannot get back to most of where it has been either, it is boxed in (its escapes
        # spent): the map holds what it could see from there, and the run says so.
        boxed_in = self._cut_off(reached)
        if boxed_in and self.unpins < self.max_unpins:
            # Before giving up: the robot may only be pinned against what it grazes, every move
            # stalling on a centimetre of position error. Once it has stepped off sideways, the moves
            # that failed are worth trying again, with a fresh budget of escapes.
            self.unpins += 1
            self.escapes = 0
            self.bumped[:] = False
            return Action("unpin", reason="unpin")
        self.given_up.update(zip(*np.nonzero(front), strict=True))
        return Action("done", reason="boxed_in" if boxed_in else "complete")

    def _probe_action(
        self,
        current: tuple[int, int],
        trav: NDArray[np.bool_],
        free_fraction: NDArray[np.float64],
        probe_cells: NDArray[np.bool_] | None,
        see_through: bool = True,
    ) -> Action | None:
        """The move towards the next probe (see ``probe``), or None when there is none."""
        if probe_cells is None:
            return None
        goal = self.probe(current, trav, probe_cells, free_fraction, see_through)
        if goal is None:
            return None
        if self.pending_look is not None and self.pending_look[0] == current:
            self.looked.add(self.pending_look)
            return Action("inspect", heading_rad=direction_heading(self.pending_look[1]), reason="probe")
        step, cell = goal
        if step == cell:
            self.probed.add(cell)
        return Action("move", step, reason="probe")

    def probe(
        self,
        current: tuple[int, int],
        trav: NDArray[np.bool_],
        probe_cells: NDArray[np.bool_],
        free_fraction: NDArray[np.float64],
        see_through: bool = True,
    ) -> tuple[tuple[int, int], tuple[int, int]] | None:
        """A navigation cell to drive into although the map holds it occupied, and the first step
        towards it (the cell itself when the robot stands beside it); None when there is none.

        Sonar arcs smear across a gap a little wider than the robot (between furniture and a
        doorway's jamb, say) and close it in the map, while the floor beyond has been seen free. A
        cell qualifies when the robot can reach a cell beside it, only echoes hold it occupied
        (``probe_cells``: no bump, nothing past the room box; the rest of it is not occupied), it has
        not been probed, and the cell
        beyond it in the same straight line is traversable but cannot be reached, and joins at least
        ``probe_min_cells`` such cells (more than a pocket behind furniture).

        A cell qualifies too, whether echoes hold it occupied or it is unknown, when every beam
        along that line from the cell beside it saw through it (``note_view``), and the cell beyond
        lies in unknown space not beside anywhere the robot can get to: a gap a cell wide beside a
        bin in a corridor longer than the sonar's range, whose beams hear nothing and clear nothing.
        When fewer than ``view_min_open`` beams saw through it, the robot first stands beside it,
        turns that way and sweeps (``pending_look``, an "inspect"), once per cell and direction.
        ``see_through`` False leaves these out.

        Driving in either arrives (the body clears the cell) or stalls (the cell is marked bumped);
        at most ``max_probes`` a run, nearest first."""
        self.pending_look = None
        see_through = see_through and bool(self.views_open.any())
        if len(self.probed) >= self.max_probes or not (probe_cells.any() or see_through):
            return None
        # Past the grid counts as wall.
        echoed = self._nav_blocks(probe_cells, False).any(axis=(1, 3))
        clear: NDArray[np.bool_] = np.asarray(
            self._nav_blocks(probe_cells | (free_fraction >= 0.0), False).all(axis=(1, 3))
        )
        has_probe: NDArray[np.bool_] = np.logical_and(echoed, clear)
        nothing = np.zeros_like(self.visited)
        no_goal = np.zeros(self.grid.shape, dtype=bool)
        # Where the robot can drive to (in breadth-first order: nearest first), and where it could
        # get to through cells it has stood in as well (one it probed may still hold echoes).
        _, reached = self._search(current, trav, no_goal, relaxed=False, seek_in=nothing)
        _, known = self._search(current, trav | self.visited, no_goal, relaxed=True, seek_in=nothing)
        blocks = self._nav_blocks(free_fraction, -1.0)
        seen_free = (blocks.min(axis=(1, 3)) >= 0.0) & (blocks.mean(axis=(1, 3)) >= self.probe_free_fraction)
        beyond = trav.copy()  # traversable cells the robot cannot get to
        for cell in known:
            beyond[cell] = False
        for cell in reached:
            for k in range(0, 8, 2):
                d = CLOCKWISE[k]
                p = (cell[0] + d[0], cell[1] + d[1])
                q = (cell[0] + 2 * d[0], cell[1] + 2 * d[1])
                if not (0 <= q[0] < self.nav_rows and 0 <= q[1] < self.nav_cols):
                    continue
                if trav[p] or self.bumped[p] or p in self.probed or not clear[p]:
                    continue
                if not (has_probe[p] and beyond[q] and self._floor_beyond(beyond, seen_free, q)):
                    # Not echoes closing a gap to floor seen free: a cell the beams from beside it
                    # saw through, to space not yet in reach?
                    far = not see_through or self.visited[p] or self._beside(q, known)
                    seen = False if far else self._sees_through(cell, k)
                    if seen is False:
                        continue
                    if seen is None:
                        self.pending_look = (cell, k)
                step = p
                if cell != current:
                    step = cell
                    while reached[step] != current:
                        step = reached[step]
                return step, p
        return None

    def _beside(self, cell: tuple[int, int], cells: Container[tuple[int, int]]) -> bool:
        """Whether ``cell`` or one of its 8 neighbours is among ``cells``."""
        return any((cell[0] + dr, cell[1] + dc) in cells for dr in (-1, 0, 1) for dc in (-1, 0, 1))

    def _floor_beyond(self, beyond: NDArray[np.bool_], seen_free: NDArray[np.bool_], start: tuple[int, int]) -> bool:
        """Whether the cells of ``beyond`` joined to ``start`` hold at least ``probe_min_cells``
        cells ``seen_free``: more than a pocket behind furniture, or a strip of the room box's face
        outside a room that is not a box."""
        joined = reachable_cells(~beyond, *start)
        return int(np.count_nonzero(joined & seen_free)) >= self.probe_min_cells

    def _cut_off(self, reached: Iterable[tuple[int, int]]) -> bool:
        """Whether a search reached fewer than half of the cells the robot has stood in."""
        return bool(2 * sum(1 for cell in reached if self.visited[cell]) < np.count_nonzero(self.visited))

    def _search(
        self,
        current: tuple[int, int],
        trav: NDArray[np.bool_],
        front: NDArray[np.bool_],
        relaxed: bool,
        seek_in: NDArray[np.bool_] | None = None,
    ) -> tuple[Action | None, dict[tuple[int, int], tuple[int, int]]]:
        """The first step towards the nearest goal (None when no goal is reachable), and the cells
        the search reached. The goals are unvisited cells, the top of the backtracking stack and
        visited cells next to the frontier (to look from); with ``seek_in``, only the cells of
        ``seek_in`` next to the frontier."""
        seek = seek_in is not None
        inspect_spots = self._inspection_spots(front, seek_in)
        stack_top = None if seek else (self.stack[-1] if self.stack else None)
        parent: dict[tuple[int, int], tuple[int, int]] = {current: current}
        queue = deque([current])
        while queue:
            cell = queue.popleft()
            goal_here = not seek and ((cell != current and not self.visited[cell]) or cell == stack_top)
            inspect_here = cell in inspect_spots
            if goal_here or (inspect_here and cell != current):
                step = cell
                while parent[step] != current:
                    step = parent[step]
                if cell == stack_top and step == cell:
                    self.stack.pop()
                return Action("move", step, reason="revisit" if goal_here else "frontier"), parent
            if inspect_here and cell == current:
                target = inspect_spots[cell]
                self.inspections[target] = self.inspections.get(target, 0) + 1
                if self.inspections[target] >= self.max_inspections:
                    self.given_up.add(target)
                return Action("inspect", heading_rad=self._heading_to(current, target), reason="frontier"), parent
            for d in CLOCKWISE:
                nxt = (cell[0] + d[0], cell[1] + d[1])
                if nxt not in parent and self._can_step(trav, cell, d, relaxed):
                    parent[nxt] = cell
                    queue.append(nxt)
        return None, parent

    def _inspection_spots(
        self, front: NDArray[np.bool_], allowed: NDArray[np.bool_] | None = None
    ) -> dict[tuple[int, int], tuple[int, int]]:
        """Navigation cells next to a frontier map cell, mapped to that cell: the visited ones, or
        those of ``allowed``."""
        spots: dict[tuple[int, int], tuple[int, int]] = {}
        b = self.block
        if allowed is None:
            allowed = self.visited
        for r, c in zip(*np.nonzero(front), strict=True):
            nav = (int(r) // b, int(c) // b)
            for d in ((0, 0), *CLOCKWISE):
                spot = (nav[0] + d[0], nav[1] + d[1])
                if 0 <= spot[0] < self.nav_rows and 0 <= spot[1] < self.nav_cols and allowed[spot]:
                    spots.setdefault(spot, (int(r), int(c)))
        return spots

    def _heading_to(self, nav: tuple[int, int], map_cell: tuple[int, int]) -> float:
        x0, y0 = self.nav_center(nav)
        x1, y1 = self.grid.index_to_world(map_cell[0], map_cell[1])
        raw = math.atan2(float(y1) - y0, float(x1) - x0)
        return direction_heading(direction_index(raw))
