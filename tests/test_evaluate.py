"""`sonarslam evaluate`: every world x seed is simulated, scored as one set (T_avg over the worlds),
tabulated with mean and worst case, and drawn as the paper's Figures 7 and 8."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from robot.cli import main
from robot.mapio import read_csv
from robot.metrics import error_ratio, score
from robot.world import load_world

# Two small rooms of different sizes (so T_avg differs from either T); a run takes well under a second.
SMALL = """
name = "small"
boundary = [[0.0, 0.0], [1.3, 0.0], [1.3, 1.1], [0.0, 1.1]]
[start]
x = 0.3
y = 0.3
theta_deg = 0.0
"""
BOXED = """
name = "boxed"
boundary = [[0.0, 0.0], [1.6, 0.0], [1.6, 1.2], [0.0, 1.2]]
[start]
x = 0.3
y = 0.3
theta_deg = 90.0
[[obstacles]]
shape = "circle"
center = [1.1, 0.7]
radius = 0.15
"""
SEEDS = 2


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, list[Path]]:
    folder = tmp_path_factory.mktemp("evaluate")
    worlds = [folder / "small.toml", folder / "boxed.toml"]
    worlds[0].write_text(SMALL)
    worlds[1].write_text(BOXED)
    out = folder / "out"
    code = main(["evaluate", *map(str, worlds), "--seeds", str(SEEDS), "--out", str(out), "--json"])
    assert code == 0
    return out, json.loads((out / "evaluation.json").read_text()), worlds


def test_every_world_and_seed_is_run_and_written(evaluated) -> None:
    out, summary, _ = evaluated
    assert summary["worlds"] == ["small", "boxed"] and summary["seeds"] == SEEDS
    assert [(r["world"], r["seed"]) for r in summary["runs"]] == [
        (w, s) for w in ("small", "boxed") for s in range(SEEDS)
    ]
    for run in summary["runs"]:
        folder = out / "runs" / run["world"] / f"seed{run['seed']}"
        estimate = read_csv(folder / "map.csv")
        truth = read_csv(folder / "truth.csv")
        assert int(np.count_nonzero(estimate != truth)) == run["metrics"]["cell_errors"]


def test_error_ratio_uses_t_avg_over_all_worlds(evaluated) -> None:
    _, summary, worlds = evaluated
    sizes = {w.name: w.grid(summary["resolution"]).total_cells for w in map(load_world, map(str, worlds))}
    t_avg = float(np.mean(list(sizes.values())))
    assert summary["t_avg"] == pytest.approx(t_avg)
    assert sizes["small"] != sizes["boxed"]
    for run in summary["runs"]:
        m = run["metrics"]
        assert m["total_cells"] == sizes[run["world"]]
        expected = error_ratio(m["cell_errors"], m["non_vacant"], m["total_cells"], t_avg)
        assert m["error_ratio"] == pytest.approx(expected, abs=1e-6)


def test_table_gives_mean_and_worst_case_per_world(evaluated) -> None:
    _, summary, _ = evaluated
    for row in summary["table"]:
        runs = [r for r in summary["runs"] if r["world"] == row["world"]]
        errors = [r["metrics"]["cell_errors"] for r in runs]
        f1 = [r["metrics"]["f1"] for r in runs]
        xy = [r["xy_cm"] for r in runs]
        assert row["mean"]["cell_errors"] == pytest.approx(np.mean(errors))
        assert row["worst"]["cell_errors"] == max(errors)
        assert row["worst"]["f1"] == pytest.approx(min(f1), abs=1e-6)
        assert row["worst"]["xy_cm"] == pytest.approx(max(xy), abs=1e-3)
        assert row["non_vacant"] == runs[0]["metrics"]["non_vacant"]


def test_scores_match_scoring_the_written_maps_directly(evaluated) -> None:
    out, summary, _ = evaluated
    run = summary["runs"][-1]
    folder = out / "runs" / run["world"] / f"seed{run['seed']}"
    direct = score(read_csv(folder / "map.csv"), read_csv(folder / "truth.csv"), summary["t_avg"])
    assert direct.f1 == pytest.approx(run["metrics"]["f1"], abs=1e-6)
    assert direct.error_ratio == pytest.approx(run["metrics"]["error_ratio"], abs=1e-6)


def test_figures_are_written(evaluated) -> None:
    out, _, _ = evaluated
    for name in ("maps.png", "scores.png"):
        with Image.open(out / name) as image:
            assert image.width > 300 and image.height > 300
    assert "T_avg" in (out / "table.txt").read_text()


def test_human_table_and_one_line_errors(evaluated, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _, _, worlds = evaluated
    assert main(["evaluate", str(worlds[0]), "--seeds", "1"]) == 0
    text = capsys.readouterr().out
    assert "small" in text and "error ratio" in text and "T_avg" in text
    assert main(["evaluate", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "missing.toml" in err


def test_bad_input_is_reported_before_the_filter_library_loads() -> None:
    # filterpy pulls in scipy.stats, about half a second: a mistyped world or setting is named first.
    code = (
        "import sys\n"
        "from robot.cli import main\n"
        "codes = [main(['run', '--world', 'nosuch']), main(['run', '--world', 'room1', '--resolution', '0.01'])]\n"
        "print(codes, 'filterpy' in sys.modules, 'scipy.stats' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.split() == ["[2,", "2]", "False", "False"]
    assert "nosuch" in done.stderr and "resolution = 0.01" in done.stderr


def test_a_setting_given_on_the_command_line_is_named_in_its_error(capsys: pytest.CaptureFixture[str]) -> None:
    # 0.01 m passes the command line's own check (a positive number) and fails the settings' bound.
    assert main(["run", "--world", "room1", "--resolution", "0.01"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "resolution = 0.01" in err and "Traceback" not in err
    assert "slam.toml" not in err  # the settings file is not to blame


def test_every_bad_setting_in_a_config_file_is_named_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "mine.toml"
    config.write_text("[slam.motion]\ntick_s = 0.001\n\n[slam.logodds.tangents]\ntheta_step_deg = 0.01\n")
    assert main(["run", "--world", "room1", "--config", str(config)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "mine.toml" in err and "Traceback" not in err
    assert "motion.tick_s" in err and "logodds.tangents.theta_step_deg" in err
    # A bad setting given on the command line is still named alone, before the file's.
    assert main(["run", "--world", "room1", "--config", str(config), "--resolution", "0.01"]) == 2
    err = capsys.readouterr().err.strip()
    assert "resolution = 0.01" in err and "tick_s" not in err
