"""Run downloads: the saved files of an ended run, or the current snapshot of a run in progress."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from robot.grid import GridSpec
from robot.mapio import csv_text, map_yaml_text, pgm_bytes, png_bytes
from robot.runner import trajectory_csv

MEDIA_TYPES = {
    "map.csv": "text/csv; charset=utf-8",
    "map.png": "image/png",
    "map.pgm": "image/x-portable-graymap",
    "map.yaml": "application/yaml",
    "trajectory.csv": "text/csv; charset=utf-8",
    "sensors.log": "text/plain; charset=utf-8",
    "bundle.zip": "application/zip",
}
BUNDLE_EXTRAS = ("truth.csv", "world.toml")  # also in the zip when the run has them


def complete_lines(path: Path) -> bytes:
    """A file being appended to, up to its last complete line."""
    data = path.read_bytes()
    return data[: data.rfind(b"\n") + 1]


def live_files(
    states: NDArray[np.int8], grid: GridSpec, trajectory: list[tuple[float, ...]], names: tuple[str, ...]
) -> dict[str, bytes]:
    """The map and trajectory files of a run in progress, made from the viewers' current map."""
    makers = {
        "map.csv": lambda: csv_text(states).encode("ascii"),
        "map.png": lambda: png_bytes(states),
        "map.pgm": lambda: pgm_bytes(states),
        "map.yaml": lambda: map_yaml_text("map.pgm", grid).encode("utf-8"),
        "trajectory.csv": lambda: trajectory_csv(trajectory).encode("ascii"),
    }
    return {name: makers[name]() for name in names if name in makers}


def read_file(run_dir: Path, name: str, live: dict[str, bytes] | None) -> bytes | None:
    """One file's bytes (None if the run has none yet): from the live snapshot when given."""
    if live is not None and name in live:
        return live[name]
    path = run_dir / name
    if not path.is_file():
        return None
    return complete_lines(path) if name == "sensors.log" else path.read_bytes()


def bundle(run_id: str, run_dir: Path, live: dict[str, bytes] | None, run_json: dict[str, object]) -> bytes:
    """A zip of every file of the run under one folder named after it, plus ``run.json``."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in (*[n for n in MEDIA_TYPES if n != "bundle.zip"], *BUNDLE_EXTRAS):
            data = read_file(run_dir, name, live)
            if data is not None:
                zf.writestr(f"{run_id}/{name}", data)
        zf.writestr(f"{run_id}/run.json", json.dumps(run_json, indent=2) + "\n")
    return buffer.getvalue()
