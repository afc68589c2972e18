"""The seed paper's map metrics (SPEC §3): cell errors, error ratio, precision, recall and F1."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robot.errors import MapFormatError
from robot.grid import FREE, OCCUPIED, UNKNOWN

_STATES = np.array([UNKNOWN, FREE, OCCUPIED], dtype=np.int8)


@dataclass(frozen=True)
class MapMetrics:
    """One map scored against its truth. Positive = black or grey, negative = white."""

    cell_errors: int  # E: cells whose black/grey/white state differs from the truth
    non_vacant: int  # N: truth black + grey cells
    total_cells: int  # T: rows x cols
    error_ratio: float  # (E / N) * (T / T_avg)
    precision: float
    recall: float
    f1: float
    true_positive: int
    false_positive: int
    false_negative: int
    true_negative: int

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-ready values, in field order."""
        return asdict(self)


def error_ratio(cell_errors: int, non_vacant: int, total_cells: int, t_avg: float | None = None) -> float:
    """The paper's ``(E / N) * (T / T_avg)``; ``t_avg`` defaults to ``total_cells`` (one map alone).

    A truth with no non-vacant cell (N = 0: a box room whose walls all lie on the grid's edges) is
    scored as if N = 1, so that the ratio stays finite and JSON-safe (0.0 when there are no errors).
    """
    if t_avg is None:
        t_avg = total_cells
    if not t_avg > 0:
        raise ValueError(f"t_avg must be positive, got {t_avg}")
    return (cell_errors / max(non_vacant, 1)) * (total_cells / t_avg)


def _ratio(numerator: int, denominator: int, empty_value: float) -> float:
    return numerator / denominator if denominator else empty_value


def _as_states(states: ArrayLike, what: str) -> NDArray[np.int8]:
    array = np.asarray(states)
    if array.ndim != 2:
        raise MapFormatError(f"{what} map must be 2-D, got shape {array.shape}")
    bad = ~np.isin(array, _STATES)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise MapFormatError(
            f"{what} map has invalid state {array[row, col].item()!r} at row {row}, col {col} (expected -1, 0 or 1)"
        )
    return array.astype(np.int8, copy=False)


def _shape_text(shape: tuple[int, ...]) -> str:
    return f"{shape[0]} x {shape[1]}"


def score(estimate: ArrayLike, truth: ArrayLike, t_avg: float | None = None) -> MapMetrics:
    """Score an estimated state grid against the truth grid (same shape, codes -1 / 0 / 1).

    Degenerate cases get defined values rather than NaN: precision is 1.0 when nothing is
    predicted positive and nothing positive was missed (else 0.0), recall is 1.0 when the truth
    has no positive and nothing was wrongly claimed positive (else 0.0), and F1 is 0.0 when
    precision + recall is 0. A perfect map therefore always scores 1.0 / 1.0 / 1.0.
    """
    est = _as_states(estimate, "estimated")
    tru = _as_states(truth, "truth")
    if est.shape != tru.shape:
        raise MapFormatError(
            f"map shape mismatch: estimate is {_shape_text(est.shape)}, truth is {_shape_text(tru.shape)} (rows x cols)"
        )
    est_pos = est != FREE
    tru_pos = tru != FREE
    tp = int(np.count_nonzero(est_pos & tru_pos))
    fp = int(np.count_nonzero(est_pos & ~tru_pos))
    fn = int(np.count_nonzero(~est_pos & tru_pos))
    tn = int(np.count_nonzero(~est_pos & ~tru_pos))
    precision = _ratio(tp, tp + fp, 1.0 if fn == 0 else 0.0)
    recall = _ratio(tp, tp + fn, 1.0 if fp == 0 else 0.0)
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    cell_errors = int(np.count_nonzero(est != tru))
    non_vacant = int(np.count_nonzero(tru_pos))
    total = int(tru.size)
    return MapMetrics(
        cell_errors=cell_errors,
        non_vacant=non_vacant,
        total_cells=total,
        error_ratio=error_ratio(cell_errors, non_vacant, total, t_avg),
        precision=precision,
        recall=recall,
        f1=f1,
        true_positive=tp,
        false_positive=fp,
        false_negative=fn,
        true_negative=tn,
    )


def score_many(pairs: Sequence[tuple[ArrayLike, ArrayLike]]) -> list[MapMetrics]:
    """Score several (estimate, truth) maps together, with T_avg = the mean T over the set."""
    if not pairs:
        return []
    sizes = [np.asarray(truth).size for _, truth in pairs]
    t_avg = float(np.mean(sizes))
    return [score(estimate, truth, t_avg) for estimate, truth in pairs]
