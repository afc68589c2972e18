"""The protocol's wire forms: integer units, and steps that carry only what changed yet fold to the full state."""

from __future__ import annotations

import random
from typing import Any

from server.broadcast import merge_steps
from server.wire import VIEW_FIELDS, StepDeltas, apply_step, sweep_wire, view_from_checkpoint


def values(t_s: float, x_mm: int, action: str, metrics: dict[str, Any] | None) -> dict[str, Any]:
    return {
        "t_s": t_s,
        "pose": [x_mm, 500, 1571],
        "sweep": [30, 400],
        "target": [x_mm, 700],
        "action": action,
        "explored": 0.25,
        "frontier": 3,
        "metrics": metrics,
    }


def test_a_step_carries_only_what_changed_since_the_step_before() -> None:
    deltas = StepDeltas()
    first = deltas.message(1, 1, values(1.5, 1500, "start", {"f1": 0.1}), [[2, 3, 0]])
    assert first == {"type": "step", "seq": 1, **values(1.5, 1500, "start", {"f1": 0.1}), "cells": [[2, 3, 0]]}
    second = deltas.message(2, 2, values(3.0, 1700, "start", {"f1": 0.1}), [])
    assert second == {"type": "step", "seq": 2, "t_s": 3.0, "pose": [1700, 500, 1571], "target": [1700, 700]}
    stop = deltas.message(3, 2, values(3.0, 1700, "stop", {"f1": 0.1}), [])
    assert stop == {"type": "step", "seq": 3, "step": 2, "action": "stop"}


def test_sonar_ranges_go_in_centimetres_and_only_no_echo_reaches_the_maximum() -> None:
    ranges = [0.304, 0.305, 3.996, 4.0, float("inf"), float("nan")]
    assert sweep_wire(ranges, 4.0) == [30, 30, 399, 400, None, None]  # half to even, as Python rounds


def test_folding_deltas_in_any_merges_gives_the_state_of_the_last_step() -> None:
    rng = random.Random(7)
    deltas = StepDeltas()
    messages, states = [], []
    for seq in range(1, 301):
        state = values(
            round(seq * 0.5, 2),
            1000 + 100 * rng.randrange(5),
            rng.choice(["explore", "explore", "backtrack"]),
            {"f1": rng.choice([0.5, 0.6])},
        )
        state["target"] = rng.choice([None, state["target"]])
        messages.append(deltas.message(seq, seq, state, []))
        states.append(state)
    # A viewer that joined at seq 40 (snapshot), merged runs of up to 9 steps, and applied them in order.
    view = {**VIEW_FIELDS, **states[39]}
    seq = 40
    while seq < 300:
        n = min(rng.randint(1, 9), 300 - seq)
        batch = messages[seq : seq + n]
        apply_step(view, merge_steps(batch) if n > 1 else batch[0])
        seq += n
        assert {k: view[k] for k in VIEW_FIELDS} == states[seq - 1]
    assert view["step"] == 300


def test_a_checkpoint_in_metres_becomes_the_wire_view() -> None:
    saved = {
        "seq": 9,
        "pose": {"x": 1.2345, "y": 0.5, "theta": -3.1416},
        "sweep": [0.3, 4.0, None],
        "target": [1.3, 0.7],
        "action": "explore",
        "progress": {"step": 9, "sim_time_s": 20.5, "explored": 0.5, "frontier": 4},
        "metrics": {"f1": 0.9},
    }
    view = view_from_checkpoint(saved, 4.0)
    assert view["pose"][1:] == [500, -3142] and view["pose"][0] in (1234, 1235)
    assert view["sweep"] == [30, 400, None] and view["target"] == [1300, 700]
    assert (view["step"], view["t_s"], view["explored"], view["frontier"]) == (9, 20.5, 0.5, 4)
    assert view["action"] == "explore" and view["metrics"] == {"f1": 0.9}
    assert view_from_checkpoint({"seq": 0}, None) == {**VIEW_FIELDS, "step": 0}
