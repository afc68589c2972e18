"""Per-viewer bounded queues: a viewer that falls behind gets its pending steps merged, never blocks the run."""

from __future__ import annotations

import asyncio
import json
import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

TERMINAL_EVENTS = frozenset({"finished", "stopped", "error", "interrupted"})
SHARED_MERGES = 64  # recent merged steps kept for other viewers
TRAIL_TOLERANCE_MM = 5.0  # a merged step's trail leaves out points its polyline passes this close to


def encode(message: dict[str, Any]) -> str:
    return json.dumps(message, separators=(",", ":"), allow_nan=False)


@dataclass
class Outgoing:
    """One wire message: the dict (for merging) and its JSON text, encoded once for every viewer.

    A step also knows when it ended on the server (``wall_time``, Unix time [s]); only viewers that
    asked for timing get it, appended to the shared text."""

    data: dict[str, Any]
    text: str = ""
    merged: bool = False  # data changed since text was made
    wall_time: float | None = None
    _timed: str | None = None
    kind: str = field(init=False)  # the message's type, asked for several times per viewer and message

    def __post_init__(self) -> None:
        self.kind = str(self.data["type"])

    @classmethod
    def of(cls, data: dict[str, Any], text: str | None = None, wall_time: float | None = None) -> Outgoing:
        return cls(data, text if text is not None else encode(data), wall_time=wall_time)

    @property
    def terminal(self) -> bool:
        return self.kind == "status" and self.data.get("event") in TERMINAL_EVENTS

    def wire(self, timing: bool = False) -> str:
        if self.merged:
            self.text = encode(self.data)
            self.merged = False
            self._timed = None
        if not timing or self.wall_time is None:
            return self.text
        if self._timed is None:
            self._timed = f'{self.text[:-1]},"wall_time":{self.wall_time!r}}}'
        return self._timed


def _off_segment_mm(p: list[int], a: list[int], b: list[int]) -> float:
    """Distance [mm] from ``p`` to the segment ``a``-``b``."""
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    px, py = p[0] - ax, p[1] - ay
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0 else min(1.0, max(0.0, (px * dx + py * dy) / length2))
    return math.hypot(px - t * dx, py - t * dy)


def _simplify_run(points: list[list[int]], tolerance_mm: float) -> list[list[int]]:
    """Douglas-Peucker on a polyline: its ends and the points it cannot leave out without straying more
    than ``tolerance_mm`` (a robot that drives straight and turns on the spot: its corners)."""
    keep = [False] * len(points)
    keep[0] = keep[-1] = True
    spans = [(0, len(points) - 1)]
    while spans:
        i, j = spans.pop()
        if j - i < 2:
            continue
        far, at = max((_off_segment_mm(points[k], points[i], points[j]), k) for k in range(i + 1, j))
        if far > tolerance_mm:
            keep[at] = True
            spans += [(i, at), (at, j)]
    return [p for p, k in zip(points, keep, strict=True) if k]


def simplify_trail(trail: list[list[Any]], end: list[Any] | None, tolerance_mm: float = TRAIL_TOLERANCE_MM
                   ) -> list[list[Any]]:  # fmt: skip
    """A merged step's trail with the points a viewer's drawn path does not need: repeats, and points on
    a straight stretch; ``end`` is where the path goes on to (the merged step's pose). The first point
    always stays (the viewer's path comes to it from a pose the merge does not know), and so does every
    point next to an unknown (``None``) position."""
    path = [*trail, end[:2]] if end is not None else list(trail)
    out: list[list[Any]] = []
    run: list[list[int]] = []
    for point in [*path, None]:
        if point is not None and None not in point:
            run.append(point)
            continue
        if run:
            out += _simplify_run(run, tolerance_mm)
            run = []
        if point is not None:
            out.append(point)
    return out[:-1] if end is not None else out  # the end itself goes as the pose


def merge_steps(steps: list[dict[str, Any]]) -> dict[str, Any]:
    """One ``step`` standing for several: the union of their cell changes (latest state per cell) and,
    of every other field, the value in the latest step that has it (a step carries only what changed);
    ``trail`` the positions the earlier steps ended at where the path turns (``simplify_trail``), so a
    viewer's trail keeps every corner; ``merged`` counts the steps it replaces."""
    out: dict[str, Any] = {}
    cells: dict[tuple[int, int], int] = {}
    trail: list[list[int]] = []  # where the robot ended each step but the last (whose end is ``pose``)
    count = 0
    for i, s in enumerate(steps):
        out.update(s)
        trail.extend(s.get("trail") or ())
        if i < len(steps) - 1:
            if s.get("pose") is not None:
                trail.append(list(s["pose"][:2]))
            elif trail:
                trail.append(trail[-1])
        for r, c, code in s.get("cells", ()):
            cells.pop((r, c), None)  # keep the order of the latest change
            cells[(r, c)] = code
        count += int(s.get("merged", 1))
    out.pop("step", None)  # absent means "equal to seq": only the last step's own says otherwise
    if "step" in steps[-1]:
        out["step"] = steps[-1]["step"]
    out.pop("trail", None)
    trail = simplify_trail(trail, out.get("pose"))
    if trail:
        out["trail"] = trail
    out.pop("cells", None)
    if cells:
        out["cells"] = [[r, c, code] for (r, c), code in cells.items()]
    out["merged"] = count
    return out


def merge(items: list[Outgoing]) -> Outgoing:
    """Steps queued for one viewer as one message, encoded when it is sent."""
    return Outgoing(merge_steps([i.data for i in items]), merged=True, wall_time=items[-1].wall_time)


class Ticker:
    """A clock whose ticks a run's viewers wait for together: one timer and one event per tick for them
    all, rather than a timer each (with 50 viewers at 25 ticks a second, the loop's wake-ups add up)."""

    def __init__(self) -> None:
        self._tick = 0  # the latest tick waited for, as a count of intervals on the loop's clock
        self._event = asyncio.Event()

    async def wait(self, interval_s: float) -> None:
        """Until the next multiple of ``interval_s`` on the loop's clock."""
        loop = asyncio.get_running_loop()
        tick = int(loop.time() // interval_s) + 1
        if self._event.is_set() and tick <= self._tick:
            tick = self._tick + 1  # the loop may run a timer a hair early: that tick has been served
        if tick != self._tick:
            self._tick = tick
            self._event = asyncio.Event()
            loop.call_at(tick * interval_s, self._event.set)
        await self._event.wait()


@dataclass(eq=False)  # compared and hashed by identity: a viewer is a viewer
class Subscriber:
    """A viewer's queue. Only the event loop touches it; ``put`` never waits."""

    maxsize: int
    items: deque[Outgoing] = field(default_factory=deque)
    merges: int = 0  # how often this viewer fell behind
    closed: bool = False
    shared: dict[tuple[int, int], Outgoing] | None = None  # merged steps, shared by a run's viewers
    _ready: asyncio.Event = field(default_factory=asyncio.Event)

    def put(self, item: Outgoing) -> None:
        if self.closed:
            return
        self.items.append(item)
        if len(self.items) > self.maxsize:
            self._compact()
        self._ready.set()

    def reset(self, snapshot: Outgoing) -> None:
        """Replace everything pending by a fresh snapshot, which already includes it (a resync)."""
        terminal = [i for i in self.items if i.terminal]
        self.items.clear()
        self.items.append(snapshot)
        self.items.extend(terminal)
        self._ready.set()

    def fold(self, first: Outgoing) -> Outgoing:
        """``first`` (a step about to be sent) merged with the steps queued right behind it."""
        steps = [first]
        shareable = self.shared is not None and "merged" not in first.data  # not a viewer's own merge
        while self.items and self.items[0].kind == "step":
            step = self.items.popleft()
            steps.append(step)
            shareable = shareable and "merged" not in step.data
        if len(steps) == 1:
            return first
        self.merges += 1
        if not shareable or self.shared is None:
            return merge(steps)
        # Viewers that keep pace fold the same steps: merge and encode them once for all.
        key = (steps[0].data["seq"], steps[-1].data["seq"])
        item = self.shared.get(key)
        if item is None:
            item = self.shared[key] = merge(steps)
            item.wire()
            while len(self.shared) > SHARED_MERGES:
                self.shared.pop(next(iter(self.shared)))
        return item

    def close(self, drop: bool = False) -> None:
        """No more messages; what is queued is still delivered unless ``drop`` (the viewer has gone)."""
        self.closed = True
        if drop:
            self.items.clear()
        self._ready.set()

    async def get(self) -> Outgoing | None:
        """The next message, or None once the queue is closed."""
        while not self.items:
            if self.closed:
                return None
            self._ready.clear()
            await self._ready.wait()
        return self.items.popleft()

    def _compact(self) -> None:
        """Fold all pending steps into one; keep the newest status of each kind, the snapshot and a pong."""
        self.merges += 1
        pending = list(self.items)
        steps = [i for i in pending if i.kind == "step"]
        snapshot = next((i for i in reversed(pending) if i.kind == "snapshot"), None)
        if snapshot is not None:
            # Steps before the snapshot are already folded into it.
            after = pending[pending.index(snapshot) + 1 :]
            steps = [i for i in after if i.kind == "step"]
        statuses: dict[str, Outgoing] = {}
        for i in pending:
            if i.kind == "status" and i.data.get("event") != "progress":
                statuses.pop(str(i.data.get("event")), None)
                statuses[str(i.data.get("event"))] = i
        rest: Iterable[Outgoing] = (i for i in pending if i.kind not in ("step", "snapshot", "status"))
        others = list(rest)[-1:]  # a pong
        self.items.clear()
        if snapshot is not None:
            self.items.append(snapshot)
        if steps:
            self.items.append(merge(steps))
        self.items.extend(sorted(statuses.values(), key=lambda i: i.terminal))
        self.items.extend(others)


class Broadcaster:
    """Fans messages out to every viewer of one run; iterates over a copy so viewers may come and go."""

    def __init__(self) -> None:
        self.subscribers: set[Subscriber] = set()
        self.shared_merges: dict[tuple[int, int], Outgoing] = {}

    def add(self, sub: Subscriber) -> None:
        sub.shared = self.shared_merges
        self.subscribers.add(sub)

    def remove(self, sub: Subscriber) -> None:
        self.subscribers.discard(sub)
        sub.close()

    def publish(self, item: Outgoing) -> None:
        for sub in tuple(self.subscribers):
            sub.put(item)

    def close_all(self) -> None:
        for sub in tuple(self.subscribers):
            sub.close()
        self.subscribers.clear()
