"""Per-viewer queues: a viewer that falls behind gets its pending steps merged, in order, without gaps."""

from __future__ import annotations

import asyncio
import itertools
import json
from typing import Any

import numpy as np
from live_client import run_async

from server.broadcast import (
    TRAIL_TOLERANCE_MM,
    Broadcaster,
    Outgoing,
    Subscriber,
    Ticker,
    _off_segment_mm,
    merge_steps,
    simplify_trail,
)


def step(seq: int, cells: list[list[int]]) -> dict[str, Any]:
    """A step as the run sends it (docs/protocol.md): pose in mm and mrad."""
    return {"type": "step", "seq": seq, "cells": cells, "pose": [100 * seq, 0, 0], "t_s": float(seq)}


def status(event: str, seq: int) -> dict[str, Any]:
    return {"type": "status", "seq": seq, "event": event}


def drain(sub: Subscriber) -> list[dict[str, Any]]:
    async def run() -> list[dict[str, Any]]:
        sub.close()
        out = []
        while (item := await sub.get()) is not None:
            out.append(item.data)
        return out

    return run_async(run())


def test_merging_keeps_the_latest_state_of_each_cell_in_order() -> None:
    merged = merge_steps([step(5, [[1, 1, 0], [2, 2, 1]]), step(6, [[1, 1, 1]]), step(7, [[3, 3, 2]])])
    assert merged["seq"] == 7 and merged["merged"] == 3 and merged["pose"] == [700, 0, 0]
    assert merged["trail"] == [[500, 0]]  # 600 lies on the way from 500 to the pose, 700
    assert merged["cells"] == [[2, 2, 1], [1, 1, 1], [3, 3, 2]]
    again = merge_steps([merged, step(8, [[2, 2, 0]])])
    assert again["merged"] == 4 and again["seq"] == 8
    assert again["cells"] == [[1, 1, 1], [3, 3, 2], [2, 2, 0]]


def test_a_full_queue_folds_its_steps_and_stays_bounded() -> None:
    sub = Subscriber(maxsize=4)
    sub.put(Outgoing.of(step(1, [[0, 0, 0]])))
    sub.put(Outgoing.of(status("started", 1)))
    for seq in range(2, 200):
        sub.put(Outgoing.of(step(seq, [[seq % 5, 0, seq % 3]])))
        sub.put(Outgoing.of(status("progress", seq)))
        assert len(sub.items) <= 4
    sub.put(Outgoing.of(status("finished", 199)))
    out = drain(sub)
    steps = [m for m in out if m["type"] == "step"]
    assert steps[-1]["seq"] == 199
    assert sum(m.get("merged", 1) for m in steps) == 199  # every step is accounted for, no gap
    assert out[-1]["event"] == "finished"
    assert sub.merges > 0
    grid = {}
    for m in steps:
        for r, c, code in m["cells"]:
            grid[(r, c)] = code
    expected = {}
    for seq in range(1, 200):
        expected[(0, 0) if seq == 1 else (seq % 5, 0)] = 0 if seq == 1 else seq % 3
    assert grid == expected


def test_a_pending_snapshot_absorbs_the_steps_before_it() -> None:
    sub = Subscriber(maxsize=3)
    sub.put(Outgoing.of(step(1, [[0, 0, 1]])))
    sub.put(Outgoing.of({"type": "snapshot", "seq": 1}))
    for seq in range(2, 6):
        sub.put(Outgoing.of(step(seq, [[seq, 0, 1]])))
    out = drain(sub)
    assert [m["type"] for m in out] == ["snapshot", "step"]
    assert out[1]["seq"] == 5 and out[1]["merged"] == 4


def test_resync_replaces_the_backlog_but_keeps_the_closing_status() -> None:
    sub = Subscriber(maxsize=10)
    for seq in range(1, 4):
        sub.put(Outgoing.of(step(seq, [])))
    sub.put(Outgoing.of(status("stopped", 3)))
    sub.reset(Outgoing.of({"type": "snapshot", "seq": 3}))
    assert [m["type"] for m in drain(sub)] == ["snapshot", "status"]


def test_a_closed_or_slow_viewer_does_not_affect_the_others() -> None:
    hub = Broadcaster()
    slow, fast, gone = Subscriber(2), Subscriber(1000), Subscriber(2)
    for sub in (slow, fast, gone):
        hub.add(sub)
    hub.remove(gone)
    for seq in range(1, 101):
        hub.publish(Outgoing.of(step(seq, [])))
    assert len(fast.items) == 100 and len(slow.items) <= 2 and not gone.items
    assert [m["seq"] for m in drain(fast)] == list(range(1, 101))


def hub_of(*viewers: Subscriber) -> Broadcaster:
    hub = Broadcaster()
    for sub in viewers:
        hub.add(sub)
    return hub


def publish_steps(hub: Broadcaster, seqs: range) -> None:
    """Steps that each change one cell of their own: row ``seq``."""
    for seq in seqs:
        hub.publish(Outgoing.of(step(seq, [[seq, 0, 1]])))


def test_viewers_that_keep_pace_share_one_merged_message() -> None:
    a, b = Subscriber(100), Subscriber(100)
    publish_steps(hub_of(a, b), range(1, 5))
    first_a, first_b = a.items.popleft(), b.items.popleft()
    merged_a, merged_b = a.fold(first_a), b.fold(first_b)
    assert merged_a is merged_b  # merged and encoded once
    assert merged_a.data["seq"] == 4 and merged_a.data["merged"] == 4
    assert '"merged":4' in merged_a.wire()
    assert not a.items and not b.items


def test_a_viewer_whose_own_queue_was_merged_does_not_take_the_shared_message() -> None:
    behind, keeping_pace = Subscriber(3), Subscriber(100)
    hub = hub_of(behind, keeping_pace)
    publish_steps(hub, range(1, 4))
    keeping_pace.fold(keeping_pace.items.popleft())  # steps 1-3 sent
    publish_steps(hub, range(4, 6))  # behind's queue overflows: steps 1-4 are folded into one
    ours = keeping_pace.fold(keeping_pace.items.popleft())  # steps 4-5
    theirs = behind.fold(behind.items.popleft())  # steps 1-5, though it too ends in steps 4 and 5
    assert ours.data["merged"] == 2 and theirs.data["merged"] == 5
    assert [c[0] for c in theirs.data["cells"]] == [1, 2, 3, 4, 5]


def test_viewers_waiting_for_the_same_tick_share_one_timer_and_each_tick_serves_once() -> None:
    async def run() -> list[float]:
        loop = asyncio.get_running_loop()
        timers: list[float] = []
        call_at = loop.call_at

        def counting_call_at(when: float, *args: Any) -> asyncio.TimerHandle:
            timers.append(when)
            return call_at(when, *args)

        loop.call_at = counting_call_at  # type: ignore[method-assign]
        ticker = Ticker()
        await ticker.wait(0.05)  # just past a tick: the next one is a whole interval away
        await asyncio.gather(*(ticker.wait(0.05) for _ in range(20)))  # twenty viewers, one timer
        assert len(timers) == 2 and timers[0] < timers[1]
        # A timer may run a hair before its time: a viewer that comes back in what still looks like
        # the tick it was woken for waits for the next one.
        early = asyncio.create_task(ticker.wait(1000.0))
        await asyncio.sleep(0)
        ticker._event.set()  # as if the loop ran the tick's timer early: its clock is short of the tick
        await early
        again = asyncio.create_task(ticker.wait(1000.0))
        await asyncio.sleep(0)
        done = again.done()
        again.cancel()
        assert not done
        return timers

    timers = run_async(run())
    assert len(timers) == 4 and timers[3] == timers[2] + 1000.0


def test_a_merged_step_carries_the_latest_value_of_every_field_that_any_merged_step_carried() -> None:
    # Each step carries only what changed since the one before it.
    steps = [
        {"type": "step", "seq": 5, "t_s": 1.0, "pose": [100, 0, 0], "sweep": [30, 400], "action": "explore"},
        {"type": "step", "seq": 6, "t_s": 2.0, "pose": [300, 0, 0], "cells": [[1, 1, 0]], "metrics": {"f1": 0.5}},
        {"type": "step", "seq": 7, "t_s": 3.0, "target": None},
    ]
    assert merge_steps(steps) == {
        "type": "step",
        "seq": 7,
        "t_s": 3.0,
        "pose": [300, 0, 0],
        "sweep": [30, 400],
        "action": "explore",
        "metrics": {"f1": 0.5},
        "target": None,
        "trail": [[100, 0]],  # where step 5 ended; step 6 ended where step 7 does, at ``pose``
        "cells": [[1, 1, 0]],
        "merged": 3,
    }
    # ``step`` is sent only when it is not ``seq`` (the stop step): only the last step's own counts.
    stop = {"type": "step", "seq": 8, "step": 7, "action": "stop"}
    assert merge_steps([steps[0], stop])["step"] == 7
    assert "step" not in merge_steps([stop, {"type": "step", "seq": 9, "t_s": 4.0}])


def test_only_viewers_that_ask_for_timing_get_the_wall_time() -> None:
    first = Outgoing.of({"type": "step", "seq": 1, "pose": [1, 2, 3]}, wall_time=1795312345.1234)
    assert first.wire() == '{"type":"step","seq":1,"pose":[1,2,3]}'
    assert json.loads(first.wire(timing=True)) == {
        "type": "step",
        "seq": 1,
        "pose": [1, 2, 3],
        "wall_time": 1795312345.1234,
    }

    hub = Broadcaster()
    sub = Subscriber(100)
    hub.add(sub)
    hub.publish(first)
    hub.publish(Outgoing.of({"type": "step", "seq": 2, "t_s": 2.0}, wall_time=1795312345.5))
    merged = sub.fold(sub.items.popleft())
    assert json.loads(merged.wire(timing=True))["wall_time"] == 1795312345.5  # the last merged step's
    assert "wall_time" not in merged.wire()


def test_a_merged_step_keeps_every_position_the_robot_ended_a_step_at() -> None:
    still = {"type": "step", "seq": 1, "t_s": 1.0}  # no pose: the robot did not move (or has none yet)
    a = {"type": "step", "seq": 2, "pose": [100, 0, 0]}
    b = {"type": "step", "seq": 3, "t_s": 2.0}
    c = {"type": "step", "seq": 4, "pose": [300, 0, 0]}
    first = merge_steps([still, a, b])
    assert first["trail"] == [[100, 0]] and first["pose"] == [100, 0, 0]  # b ended where a did: at pose
    # Merging a merged step again keeps its trail, oldest first, and the corners of the path.
    again = merge_steps([first, c, {"type": "step", "seq": 5, "pose": [300, 200, 0]}])
    assert again["trail"] == [[100, 0], [300, 0]] and again["merged"] == 5
    assert "trail" not in merge_steps([still, {"type": "step", "seq": 2, "t_s": 2.0}])


def test_a_merged_trail_keeps_the_corners_and_leaves_out_straight_stretches() -> None:
    # Cell moves of 200 mm with a turn on the spot (a repeated point) and a 2 mm wobble.
    trail = [[0, 0], [200, 0], [400, 2], [400, 2], [600, 0], [600, 200], [600, 400]]
    assert simplify_trail(trail, [800, 600, 785]) == [[0, 0], [600, 0], [600, 400]]
    # A bend wider than the tolerance stays; an unknown position breaks the path on both sides.
    assert simplify_trail([[0, 0], [100, 6], [200, 0]], [200, 300, 0]) == [[0, 0], [100, 6], [200, 0]]
    broken = [[0, 0], [100, 0], [None, None], [300, 0], [400, 0]]
    assert simplify_trail(broken, [500, 0, 0]) == [[0, 0], [100, 0], [None, None], [300, 0]]
    # Whatever it leaves out lies within the tolerance of the path it keeps.
    rng = np.random.default_rng(3)
    walk = np.cumsum(rng.choice([-200, 0, 200], size=(300, 2)), axis=0).tolist()
    kept = simplify_trail(walk[:-1], walk[-1])
    path = [*kept, walk[-1]]
    for p in walk:
        assert min(_off_segment_mm(p, a, b) for a, b in itertools.pairwise(path)) <= TRAIL_TOLERANCE_MM
    assert len(kept) < len(walk) - 1
