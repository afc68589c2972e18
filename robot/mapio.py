"""Map files (SPEC §4): CSV, PNG and ROS map_server PGM + YAML, written atomically, read strictly."""

from __future__ import annotations

import io
import json
import math
import os
import re
import tempfile
from pathlib import Path
from typing import TypeAlias

import numpy as np
from numpy.typing import ArrayLike, NDArray
from PIL import Image, UnidentifiedImageError

from robot.errors import MapFormatError
from robot.grid import FREE, OCCUPIED, UNKNOWN, GridSpec

PNG_BLACK, PNG_WHITE, PNG_GREY = 0, 255, 128
PGM_OCCUPIED, PGM_FREE, PGM_UNKNOWN = 0, 254, 205
ROS_OCCUPIED_THRESH = 0.65
ROS_FREE_THRESH = 0.196

_PGM_FIELD = re.compile(rb"(?:\s|#[^\n]*\n)+(\d+)")  # whitespace or comments, then a number

StrPath: TypeAlias = str | os.PathLike[str]


def _check_states(states: ArrayLike) -> NDArray[np.int8]:
    array = np.asarray(states)
    if array.ndim != 2 or array.size == 0:
        raise MapFormatError(f"a map must be a non-empty 2-D array, got shape {array.shape}")
    bad = ~np.isin(array, (UNKNOWN, FREE, OCCUPIED))
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise MapFormatError(
            f"invalid map state {array[row, col].item()!r} at row {row}, col {col} (expected -1, 0 or 1)"
        )
    return array.astype(np.int8, copy=False)


def atomic_write_bytes(path: StrPath, data: bytes) -> Path:
    """Write ``data`` to a temporary file next to ``path`` and rename it into place."""
    target = Path(path)
    fd, tmp_name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        # mkstemp makes the file private (0600); a map is an ordinary file, so keep the old mode or use 0644.
        os.chmod(tmp_name, target.stat().st_mode & 0o777 if target.exists() else 0o644)
        os.replace(tmp_name, target)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return target


def _read_bytes(path: StrPath) -> bytes:
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise MapFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _check_shape(path: StrPath, shape: tuple[int, int], expected: tuple[int, int] | None) -> None:
    if expected is not None and tuple(expected) != shape:
        raise MapFormatError(
            f"{path}: map is {shape[0]} x {shape[1]} (rows x cols), expected {expected[0]} x {expected[1]}"
        )


# --- CSV -----------------------------------------------------------------------------------------


def csv_text(states: ArrayLike) -> str:
    """The SPEC §4 CSV text: one line per row, top row first, ``1`` / ``0`` / empty for unknown."""
    array = _check_states(states)
    tokens = np.where(array == OCCUPIED, "1", np.where(array == FREE, "0", ""))
    return "".join(",".join(row) + "\n" for row in tokens)


def write_csv(path: StrPath, states: ArrayLike) -> Path:
    """Write ``map.csv`` (SPEC §4) atomically."""
    return atomic_write_bytes(path, csv_text(states).encode("ascii"))


def parse_csv(text: str, source: str = "<csv>", expected_shape: tuple[int, int] | None = None) -> NDArray[np.int8]:
    """Parse SPEC §4 CSV text; every problem is a MapFormatError naming ``source`` and the line."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()  # the final newline ends the last row; it does not start another
    lines = [line.removesuffix("\r") for line in lines]
    if not lines:
        raise MapFormatError(f"{source}: empty map file")
    fields = [[token.strip() for token in line.split(",")] for line in lines]
    cols = len(fields[0])
    for number, row in enumerate(fields, start=1):
        if len(row) != cols:
            raise MapFormatError(f"{source}: line {number}: {len(row)} fields, expected {cols} (as on line 1)")
    tokens = np.array(fields, dtype=str).reshape(len(fields), cols)
    states = np.full(tokens.shape, UNKNOWN, dtype=np.int8)
    states[tokens == "1"] = OCCUPIED
    states[tokens == "0"] = FREE
    bad = ~np.isin(tokens, ("1", "0", ""))
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise MapFormatError(
            f"{source}: line {row + 1}, field {col + 1}: bad value {str(tokens[row, col])!r} (expected 1, 0 or empty)"
        )
    _check_shape(source, (states.shape[0], states.shape[1]), expected_shape)
    return states


def read_csv(path: StrPath, expected_shape: tuple[int, int] | None = None) -> NDArray[np.int8]:
    """Read ``map.csv`` into an int8 state grid (-1 unknown, 0 free, 1 occupied)."""
    raw = _read_bytes(path)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise MapFormatError(f"{path}: not a text file (invalid UTF-8)") from None
    return parse_csv(text, str(path), expected_shape)


# --- PNG -----------------------------------------------------------------------------------------


def default_pixels_per_cell(rows: int, cols: int, min_long_side_px: int = 400, max_pixels_per_cell: int = 32) -> int:
    """The smallest whole scale that makes the long side at least ``min_long_side_px``, capped."""
    return max(1, min(max_pixels_per_cell, math.ceil(min_long_side_px / max(rows, cols))))


def png_bytes(states: ArrayLike, pixels_per_cell: int | None = None) -> bytes:
    """Greyscale PNG of the map: black occupied, white free, grey (128) unknown, top row first."""
    array = _check_states(states)
    scale = pixels_per_cell if pixels_per_cell is not None else default_pixels_per_cell(*array.shape)
    if not isinstance(scale, (int, np.integer)) or scale < 1:
        raise ValueError(f"pixels_per_cell must be a positive integer, got {pixels_per_cell!r}")
    grey = np.full(array.shape, PNG_GREY, dtype=np.uint8)
    grey[array == OCCUPIED] = PNG_BLACK
    grey[array == FREE] = PNG_WHITE
    pixels = np.repeat(np.repeat(grey, scale, axis=0), scale, axis=1)
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="PNG")
    return buffer.getvalue()


def write_png(path: StrPath, states: ArrayLike, pixels_per_cell: int | None = None) -> Path:
    """Write ``map.png`` (SPEC §4) atomically."""
    return atomic_write_bytes(path, png_bytes(states, pixels_per_cell))


def read_png(path: StrPath, rows: int, cols: int) -> NDArray[np.int8]:
    """Read a map PNG of ``rows`` x ``cols`` cells back into states, sampling each cell's centre pixel."""
    try:
        with Image.open(io.BytesIO(_read_bytes(path))) as image:
            pixels = np.asarray(image.convert("L"))
    except (UnidentifiedImageError, OSError) as exc:
        raise MapFormatError(f"{path}: not a readable PNG: {exc}") from None
    height, width = pixels.shape
    if height % rows or width % cols or height // rows != width // cols:
        raise MapFormatError(
            f"{path}: image is {width} x {height} px, not a whole number of square pixels per cell "
            f"for {rows} x {cols} cells (rows x cols)"
        )
    scale = height // rows
    centres = pixels[scale // 2 :: scale, scale // 2 :: scale]
    states = np.full(centres.shape, UNKNOWN, dtype=np.int8)
    states[centres == PNG_BLACK] = OCCUPIED
    states[centres == PNG_WHITE] = FREE
    bad = ~np.isin(centres, (PNG_BLACK, PNG_WHITE, PNG_GREY))
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise MapFormatError(f"{path}: cell row {row}, col {col} has grey level {centres[row, col]}, not 0, 128 or 255")
    return states


# --- ROS map_server PGM + YAML ---------------------------------------------------------------------


def pgm_bytes(states: ArrayLike) -> bytes:
    """Binary P5 PGM, one pixel per cell, top row first: occupied 0, free 254, unknown 205."""
    array = _check_states(states)
    pixels = np.full(array.shape, PGM_UNKNOWN, dtype=np.uint8)
    pixels[array == OCCUPIED] = PGM_OCCUPIED
    pixels[array == FREE] = PGM_FREE
    rows, cols = array.shape
    return f"P5\n{cols} {rows}\n255\n".encode("ascii") + pixels.tobytes()


def _yaml_string(text: str) -> str:
    return text if re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.\-]*", text) else json.dumps(text)


def map_yaml_text(image_name: str, grid: GridSpec) -> str:
    """The map_server YAML; ``origin`` is the world pose of the lower-left pixel (the grid origin)."""
    return (
        f"image: {_yaml_string(image_name)}\n"
        f"resolution: {float(grid.resolution)!r}\n"
        f"origin: [{float(grid.origin_x)!r}, {float(grid.origin_y)!r}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {ROS_OCCUPIED_THRESH}\n"
        f"free_thresh: {ROS_FREE_THRESH}\n"
        "mode: trinary\n"
    )


def write_pgm_yaml(pgm_path: StrPath, yaml_path: StrPath, states: ArrayLike, grid: GridSpec) -> tuple[Path, Path]:
    """Write ``map.pgm`` and ``map.yaml`` (SPEC §4) atomically.

    The YAML names the image relative to the YAML's folder, as map_server resolves it; that is
    the PGM's basename when both files share a folder, as they should.
    """
    array = _check_states(states)
    if array.shape != grid.shape:
        raise MapFormatError(
            f"map is {array.shape[0]} x {array.shape[1]} (rows x cols) but the grid is {grid.rows} x {grid.cols}"
        )
    pgm = atomic_write_bytes(pgm_path, pgm_bytes(array))
    image_name = Path(os.path.relpath(Path(pgm_path).resolve(), Path(yaml_path).resolve().parent)).as_posix()
    yaml = atomic_write_bytes(yaml_path, map_yaml_text(image_name, grid).encode("utf-8"))
    return pgm, yaml


def _pgm_header(data: bytes, source: str) -> tuple[int, int, int, int]:
    """(width, height, maxval, offset of the first pixel byte) of a P5 PGM, comments allowed."""
    values: list[int] = []
    pos = 2
    if data[:2] != b"P5":
        raise MapFormatError(f"{source}: not a binary PGM (expected magic 'P5')")
    while len(values) < 3:
        match = _PGM_FIELD.match(data, pos)
        if match is None:
            raise MapFormatError(f"{source}: truncated or malformed PGM header")
        values.append(int(match.group(1)))
        pos = match.end()
    if pos >= len(data) or data[pos : pos + 1] not in (b" ", b"\t", b"\n", b"\r"):
        raise MapFormatError(f"{source}: malformed PGM header")
    width, height, maxval = values
    if width < 1 or height < 1 or not 0 < maxval < 256:
        raise MapFormatError(f"{source}: unsupported PGM size {width} x {height} or maxval {maxval}")
    return width, height, maxval, pos + 1


def read_pgm(path: StrPath, expected_shape: tuple[int, int] | None = None) -> NDArray[np.int8]:
    """Read a P5 PGM map with map_server's trinary rule (negate 0, thresholds 0.65 / 0.196)."""
    data = _read_bytes(path)
    width, height, maxval, offset = _pgm_header(data, str(path))
    body = data[offset : offset + width * height]
    if len(body) != width * height:
        raise MapFormatError(f"{path}: PGM has {len(body)} pixel bytes, expected {width * height}")
    pixels = np.frombuffer(body, dtype=np.uint8).reshape(height, width).astype(float)
    occupancy = (maxval - pixels) / maxval
    states = np.full((height, width), UNKNOWN, dtype=np.int8)
    states[occupancy > ROS_OCCUPIED_THRESH] = OCCUPIED
    states[occupancy < ROS_FREE_THRESH] = FREE
    _check_shape(path, (height, width), expected_shape)
    return states


# --- conveniences --------------------------------------------------------------------------------


def write_map_files(out_dir: StrPath, states: ArrayLike, grid: GridSpec, stem: str = "map") -> dict[str, Path]:
    """Write ``{stem}.csv``, ``.png``, ``.pgm`` and ``.yaml`` into ``out_dir`` (created if needed)."""
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    array = _check_states(states)
    pgm, yaml = write_pgm_yaml(folder / f"{stem}.pgm", folder / f"{stem}.yaml", array, grid)
    return {
        "csv": write_csv(folder / f"{stem}.csv", array),
        "png": write_png(folder / f"{stem}.png", array),
        "pgm": pgm,
        "yaml": yaml,
    }


def write_truth_files(out_dir: StrPath, states: ArrayLike, grid: GridSpec) -> dict[str, Path]:
    """Write ``truth.csv`` and ``truth.png`` into ``out_dir`` (created if needed)."""
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    array = _check_states(states)
    if array.shape != grid.shape:
        raise MapFormatError(
            f"truth is {array.shape[0]} x {array.shape[1]} (rows x cols) but the grid is {grid.rows} x {grid.cols}"
        )
    return {"csv": write_csv(folder / "truth.csv", array), "png": write_png(folder / "truth.png", array)}
