"""Map files (SPEC §4): exact CSV / PGM / YAML contents, PNG scaling, round trips and strict reading."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from robot.errors import MapFormatError
from robot.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from robot.mapio import (
    read_csv,
    read_pgm,
    read_png,
    write_csv,
    write_map_files,
    write_pgm_yaml,
    write_png,
    write_truth_files,
)

B, W, G = int(OCCUPIED), int(FREE), int(UNKNOWN)
TINY = np.array([[B, W, G], [G, G, W]], dtype=np.int8)


def random_states(rows: int, cols: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).choice(np.array([G, W, B], dtype=np.int8), size=(rows, cols))


# --- CSV -----------------------------------------------------------------------------------------


def test_csv_of_a_tiny_grid_is_exact(tmp_path: Path) -> None:
    path = write_csv(tmp_path / "map.csv", TINY)
    assert path.read_bytes() == b"1,0,\n,,0\n"


@pytest.mark.parametrize("shape", [(1, 1), (1, 7), (7, 1), (23, 17)])
def test_csv_round_trip(tmp_path: Path, shape: tuple[int, int]) -> None:
    states = random_states(*shape)
    write_csv(tmp_path / "map.csv", states)
    back = read_csv(tmp_path / "map.csv", expected_shape=shape)
    assert back.dtype == np.int8
    np.testing.assert_array_equal(back, states)


def test_csv_of_an_all_unknown_column_round_trips(tmp_path: Path) -> None:
    states = np.full((3, 1), G, dtype=np.int8)
    write_csv(tmp_path / "map.csv", states)
    assert (tmp_path / "map.csv").read_text() == "\n\n\n"
    np.testing.assert_array_equal(read_csv(tmp_path / "map.csv"), states)


def test_csv_reader_accepts_crlf_spaces_and_a_missing_final_newline(tmp_path: Path) -> None:
    path = tmp_path / "windows.csv"
    path.write_bytes(b"1, 0 ,\r\n,,0")
    np.testing.assert_array_equal(read_csv(path), TINY)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"1,0,\n,0\n", r"line 2: 2 fields, expected 3"),
        (b"1,0,1\n0,x,1\n", r"line 2, field 2: bad value 'x'"),
        (b"1,0,1\n0,-1,1\n", r"line 2, field 2: bad value '-1'"),
        (b"1,0.0\n", r"line 1, field 2: bad value '0.0'"),
        (b"", r"empty map file"),
        (b"\xff\xfe1,0\n", r"not a text file"),
    ],
)
def test_bad_csv_is_a_map_format_error_naming_the_file(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "broken.csv"
    path.write_bytes(content)
    with pytest.raises(MapFormatError, match=message) as info:
        read_csv(path)
    assert str(path) in str(info.value)


def test_csv_of_the_wrong_size_names_both_sizes(tmp_path: Path) -> None:
    path = write_csv(tmp_path / "map.csv", TINY)
    with pytest.raises(MapFormatError, match=r"map\.csv: map is 2 x 3 \(rows x cols\), expected 3 x 2"):
        read_csv(path, expected_shape=(3, 2))


def test_missing_csv_is_a_map_format_error(tmp_path: Path) -> None:
    with pytest.raises(MapFormatError, match=r"nothing\.csv: cannot read"):
        read_csv(tmp_path / "nothing.csv")


def test_writers_reject_states_outside_the_three_codes(tmp_path: Path) -> None:
    with pytest.raises(MapFormatError, match="invalid map state 7"):
        write_csv(tmp_path / "map.csv", np.array([[0, 7]]))
    with pytest.raises(MapFormatError, match="2-D"):
        write_png(tmp_path / "map.png", np.zeros(3))
    assert not any(tmp_path.iterdir())


# --- atomic writes -------------------------------------------------------------------------------


def test_written_files_are_not_private(tmp_path: Path) -> None:
    path = write_csv(tmp_path / "map.csv", TINY)
    assert path.stat().st_mode & 0o777 == 0o644
    path.chmod(0o664)
    write_csv(path, TINY)
    assert path.stat().st_mode & 0o777 == 0o664


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = write_csv(tmp_path / "map.csv", TINY)

    def crash(src: str, dst: str) -> None:
        raise OSError("disk unplugged")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError, match="disk unplugged"):
        write_csv(path, np.zeros((2, 3), dtype=np.int8))
    assert path.read_bytes() == b"1,0,\n,,0\n"
    assert [p.name for p in tmp_path.iterdir()] == ["map.csv"]


# --- PNG -----------------------------------------------------------------------------------------


def test_png_uses_three_grey_levels_and_whole_square_cells(tmp_path: Path) -> None:
    path = write_png(tmp_path / "map.png", TINY, pixels_per_cell=4)
    with Image.open(path) as image:
        assert image.mode == "L"
        assert image.size == (12, 8)  # width = 3 cols x 4 px, height = 2 rows x 4 px
        pixels = np.asarray(image)
    expected = np.array([[0, 255, 128], [128, 128, 255]], dtype=np.uint8)
    np.testing.assert_array_equal(pixels, np.kron(expected, np.ones((4, 4), dtype=np.uint8)))


def test_png_default_scale_makes_a_readable_image(tmp_path: Path) -> None:
    path = write_png(tmp_path / "map.png", random_states(23, 17))
    with Image.open(path) as image:
        width, height = image.size
    assert height % 23 == 0 and width % 17 == 0 and height // 23 == width // 17
    assert max(width, height) >= 400
    np.testing.assert_array_equal(read_png(path, 23, 17), random_states(23, 17))


def test_png_default_scale_is_capped_for_tiny_maps(tmp_path: Path) -> None:
    path = write_png(tmp_path / "map.png", np.zeros((1, 1), dtype=np.int8))
    with Image.open(path) as image:
        assert image.size[0] == image.size[1] <= 64


def test_png_read_with_the_wrong_grid_is_an_error(tmp_path: Path) -> None:
    path = write_png(tmp_path / "map.png", TINY, pixels_per_cell=5)
    with pytest.raises(MapFormatError, match=r"map\.png: image is 15 x 10 px"):
        read_png(path, 3, 2)


def test_png_read_of_a_non_image_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "map.png"
    path.write_text("not a png")
    with pytest.raises(MapFormatError, match=r"map\.png: not a readable PNG"):
        read_png(path, 1, 1)


# --- ROS map_server PGM + YAML -----------------------------------------------------------------


def test_pgm_header_and_bytes_are_exact(tmp_path: Path) -> None:
    grid = GridSpec(origin_x=0.0, origin_y=0.0, resolution=0.2, rows=2, cols=3)
    pgm, _ = write_pgm_yaml(tmp_path / "map.pgm", tmp_path / "map.yaml", TINY, grid)
    assert pgm.read_bytes() == b"P5\n3 2\n255\n" + bytes([0, 254, 205, 205, 205, 254])


def test_yaml_is_exact_and_points_at_the_pgm(tmp_path: Path) -> None:
    grid = GridSpec(origin_x=-1.5, origin_y=2.25, resolution=0.05, rows=2, cols=3)
    _, yaml = write_pgm_yaml(tmp_path / "room.pgm", tmp_path / "room.yaml", TINY, grid)
    assert yaml.read_text() == (
        "image: room.pgm\n"
        "resolution: 0.05\n"
        "origin: [-1.5, 2.25, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
        "mode: trinary\n"
    )
    pyyaml = pytest.importorskip("yaml")
    assert pyyaml.safe_load(yaml.read_text()) == {
        "image": "room.pgm",
        "resolution": 0.05,
        "origin": [-1.5, 2.25, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        "mode": "trinary",
    }


def test_pgm_round_trip(tmp_path: Path) -> None:
    states = random_states(22, 17, seed=4)
    grid = GridSpec(origin_x=0.0, origin_y=0.0, resolution=0.2, rows=22, cols=17)
    pgm, _ = write_pgm_yaml(tmp_path / "map.pgm", tmp_path / "map.yaml", states, grid)
    np.testing.assert_array_equal(read_pgm(pgm, expected_shape=(22, 17)), states)


def test_pgm_reader_applies_map_server_thresholds_and_skips_comments(tmp_path: Path) -> None:
    path = tmp_path / "other.pgm"
    # 10 -> p = 0.96 occupied; 100 -> p = 0.61 unknown; 250 -> p = 0.02 free.
    path.write_bytes(b"P5\n# made by another tool\n3 1\n# max\n255\n" + bytes([10, 100, 250]))
    np.testing.assert_array_equal(read_pgm(path), [[B, G, W]])


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"P2\n1 1\n255\n0", "not a binary PGM"),
        (b"P5\n3 1\n255\n\x00", "1 pixel bytes, expected 3"),
        (b"P5\n3", "malformed PGM header"),
        (b"P5\n3 1", "truncated or malformed PGM header"),
        (b"P5\n0 1\n255\n", "unsupported PGM size"),
    ],
)
def test_bad_pgm_is_a_map_format_error_naming_the_file(tmp_path: Path, content: bytes, message: str) -> None:
    path = tmp_path / "bad.pgm"
    path.write_bytes(content)
    with pytest.raises(MapFormatError, match=message) as info:
        read_pgm(path)
    assert str(path) in str(info.value)


def test_pgm_writer_checks_the_grid_shape(tmp_path: Path) -> None:
    grid = GridSpec(origin_x=0.0, origin_y=0.0, resolution=0.2, rows=3, cols=2)
    with pytest.raises(MapFormatError, match=r"map is 2 x 3 \(rows x cols\) but the grid is 3 x 2"):
        write_pgm_yaml(tmp_path / "map.pgm", tmp_path / "map.yaml", TINY, grid)


# --- conveniences --------------------------------------------------------------------------------


def test_write_map_and_truth_files(tmp_path: Path) -> None:
    grid = GridSpec(origin_x=0.0, origin_y=0.0, resolution=0.2, rows=2, cols=3)
    out = tmp_path / "run" / "out"
    paths = write_map_files(out, TINY, grid)
    truth = write_truth_files(out, TINY, grid)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["map.csv", "map.pgm", "map.png", "map.yaml", "truth.csv", "truth.png"]
    assert paths["csv"].read_bytes() == truth["csv"].read_bytes() == b"1,0,\n,,0\n"
    np.testing.assert_array_equal(read_pgm(paths["pgm"]), TINY)
    np.testing.assert_array_equal(read_png(truth["png"], 2, 3), TINY)
