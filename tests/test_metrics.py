"""The paper's metrics (SPEC §3): Table I error ratios, precision / recall / F1 and edge cases."""

from __future__ import annotations

import json

import numpy as np
import pytest

from robot.errors import MapFormatError
from robot.grid import FREE, OCCUPIED, UNKNOWN
from robot.metrics import MapMetrics, error_ratio, score, score_many
from robot.truth import truth_grid
from robot.world import builtin_worlds, load_world, world_from_dict

B, W, G = int(OCCUPIED), int(FREE), int(UNKNOWN)

# The paper's Table I: (E, N, T) per room and the printed error ratio.
TABLE_I = [((1, 6, 391), 0.1877), ((38, 106, 256), 0.2643), ((7, 149, 374), 0.0506), ((16, 242, 368), 0.0701)]
PAPER_SHAPES = [(23, 17), (16, 16), (22, 17), (23, 16)]


def confusion(metrics: MapMetrics) -> tuple[int, int, int, int]:
    """(TP, FP, FN, TN)."""
    return (metrics.true_positive, metrics.false_positive, metrics.false_negative, metrics.true_negative)


def test_table_i_error_ratios() -> None:
    t_avg = sum(t for (_, _, t), _ in TABLE_I) / len(TABLE_I)
    assert t_avg == 347.25
    for (e, n, t), printed in TABLE_I:
        assert round(error_ratio(e, n, t, t_avg), 4) == printed


def synthetic_pair(e: int, n: int, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """A truth with ``n`` non-vacant cells and an estimate that differs from it in ``e`` cells."""
    truth = np.full(shape[0] * shape[1], W, dtype=np.int8)
    truth[:n] = np.where(np.arange(n) % 2 == 0, B, G)
    estimate = truth.copy()
    estimate[:e] = np.where(truth[:e] == W, B, W)
    return estimate.reshape(shape), truth.reshape(shape)


def test_score_many_reproduces_table_i_with_the_mean_grid_size() -> None:
    pairs = [synthetic_pair(e, n, shape) for ((e, n, _), _), shape in zip(TABLE_I, PAPER_SHAPES, strict=True)]
    results = score_many(pairs)
    for metrics, ((e, n, t), printed) in zip(results, TABLE_I, strict=True):
        assert (metrics.cell_errors, metrics.non_vacant, metrics.total_cells) == (e, n, t)
        assert round(metrics.error_ratio, 4) == printed


def test_one_map_alone_uses_its_own_size() -> None:
    estimate, truth = synthetic_pair(38, 106, (16, 16))
    assert score(estimate, truth).error_ratio == pytest.approx(38 / 106)
    assert error_ratio(38, 106, 256) == pytest.approx(38 / 106)
    assert score_many([]) == []


@pytest.mark.parametrize("name", sorted(builtin_worlds()))
def test_a_world_truth_scored_against_itself_is_perfect(name: str) -> None:
    _, truth = truth_grid(load_world(name), 0.2)
    metrics = score(truth.copy(), truth)
    assert metrics.cell_errors == 0
    assert metrics.error_ratio == 0.0
    assert (metrics.precision, metrics.recall, metrics.f1) == (1.0, 1.0, 1.0)
    assert metrics.total_cells == truth.size
    assert metrics.non_vacant == int((truth != FREE).sum())


def test_an_all_grey_map_of_a_small_room_worked_by_hand() -> None:
    # 1 m x 0.6 m at 0.2 m = 3 x 5 cells. The obstacle pokes 1 mm into columns 2 and 4 of the top
    # row, so the truth is three black cells (top row, columns 2..4) and twelve white ones.
    world = world_from_dict(
        {
            "boundary": [[0.0, 0.0], [1.0, 0.0], [1.0, 0.6], [0.0, 0.6]],
            "start": {"x": 0.1, "y": 0.1, "theta_deg": 0.0},
            "obstacles": [{"shape": "rect", "center": [0.7, 0.5], "size": [0.202, 0.2]}],
        },
        "small.toml",
    )
    grid, truth = truth_grid(world, 0.2)
    np.testing.assert_array_equal(truth, [[W, W, B, B, B], [W] * 5, [W] * 5])
    metrics = score(grid.empty(), truth)
    # Every cell is predicted positive: TP = 3 black, FP = 12 white, FN = 0.
    assert confusion(metrics) == (3, 12, 0, 0)
    assert metrics.recall == 1.0
    assert metrics.precision == 3 / 15 == 0.2
    assert metrics.f1 == pytest.approx(2 * 0.2 * 1.0 / 1.2)
    # Grey differs from black too: all 15 cells are errors; N = 3, T = 15.
    assert metrics.cell_errors == 15
    assert metrics.non_vacant == 3
    assert metrics.error_ratio == 5.0


def test_black_and_grey_are_both_positive_but_distinct_states() -> None:
    truth = np.array([[B, G, W, W]], dtype=np.int8)
    estimate = np.array([[G, B, W, B]], dtype=np.int8)
    metrics = score(estimate, truth)
    assert metrics.cell_errors == 3
    assert confusion(metrics) == (2, 1, 0, 1)
    assert metrics.precision == pytest.approx(2 / 3)
    assert metrics.recall == 1.0
    assert metrics.f1 == pytest.approx(0.8)


def test_degenerate_cases_have_defined_values() -> None:
    white = np.zeros((2, 3), dtype=np.int8)
    perfect = score(white, white)  # no positives anywhere and N = 0
    assert (perfect.precision, perfect.recall, perfect.f1, perfect.error_ratio) == (1.0, 1.0, 1.0, 0.0)

    one_wrong_grey = white.copy()
    one_wrong_grey[0, 0] = G
    claimed = score(one_wrong_grey, white)  # N = 0 is scored as N = 1
    assert (claimed.precision, claimed.recall, claimed.f1) == (0.0, 0.0, 0.0)
    assert claimed.error_ratio == 1.0

    missed = score(white, one_wrong_grey)  # nothing predicted positive, one positive missed
    assert (missed.precision, missed.recall, missed.f1) == (0.0, 0.0, 0.0)
    assert missed.error_ratio == 1.0


def test_shape_mismatch_names_both_shapes() -> None:
    with pytest.raises(MapFormatError, match=r"estimate is 3 x 5, truth is 5 x 3 \(rows x cols\)"):
        score(np.zeros((3, 5), dtype=np.int8), np.zeros((5, 3), dtype=np.int8))


def test_invalid_states_are_rejected() -> None:
    with pytest.raises(MapFormatError, match="invalid state 2 at row 0, col 1"):
        score(np.array([[0, 2]]), np.array([[0, 0]]))
    with pytest.raises(MapFormatError, match="2-D"):
        score(np.zeros(4), np.zeros(4))


def test_as_dict_is_json_ready_and_carries_the_spec_keys() -> None:
    estimate, truth = synthetic_pair(7, 149, (22, 17))
    metrics = score(estimate, truth)
    data = metrics.as_dict()
    assert list(data) == [f for f in MapMetrics.__dataclass_fields__]
    for key in ("cell_errors", "non_vacant", "total_cells", "error_ratio", "precision", "recall", "f1"):
        assert key in data
    assert type(data["cell_errors"]) is int and type(data["f1"]) is float
    assert json.loads(json.dumps(data)) == data
    with pytest.raises(AttributeError):
        metrics.f1 = 0.5  # type: ignore[misc]


def test_error_ratio_rejects_a_non_positive_average() -> None:
    with pytest.raises(ValueError, match="t_avg"):
        error_ratio(1, 2, 3, 0)
