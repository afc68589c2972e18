"""The dashboard in headless Chromium against a real service: start a run, watch it, stop it, download."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import pytest
from browser_kit import Dashboard, Service, parse_map_csv, wait_until

pytestmark = pytest.mark.browser

ROBOT_ORANGE = (232, 89, 12)


def finished_run(service: Service, **params: Any) -> str:
    """Start a run through REST at full speed and wait for it to end."""
    res = service.api("POST", "/api/runs", json={"world": "room2", "speed": "max", **params})
    assert res.status_code == 201, res.text
    run_id = str(res.json()["id"])
    wait_until(
        lambda: service.api("GET", f"/api/runs/{run_id}").json()["status"] in ("finished", "stopped", "error"),
        60,
        f"run {run_id} to end",
    )
    return run_id


def assert_canvas_shows(dashboard: Dashboard, expected: list[list[int]]) -> None:
    """Every cell's pixel on screen has the colour of its state in ``expected`` (map.csv)."""
    dashboard.hide_overlays()
    sampled = dashboard.sample_cells()
    rows, cols = len(expected), len(expected[0])
    assert len(sampled) == rows * cols
    wrong = [(rc, got, expected[rc[0]][rc[1]]) for rc, got in sampled.items() if got != expected[rc[0]][rc[1]]]
    assert wrong == [], (
        f"{len(wrong)} of {rows * cols} cells differ from map.csv (cell, on screen, in csv): {wrong[:10]}"
    )


def test_page_loads_with_labelled_controls_and_fits_a_phone(dashboard: Dashboard, expect: Any) -> None:
    dashboard.open()
    page = dashboard.page
    worlds = page.locator("#world option").all_text_contents()
    assert any(w.startswith("room2") for w in worlds)
    for label in ("World", "Mapper", "Resolution (m per cell)", "Speed (times real time)", "Seed"):
        expect(page.get_by_label(label, exact=True)).to_be_visible()
    expect(page.get_by_role("button", name="Start run")).to_be_enabled()
    expect(page.get_by_role("button", name="Stop run")).to_be_disabled()

    # Keyboard: the skip link comes first, then focus moves through real controls.
    page.keyboard.press("Tab")
    assert page.evaluate("document.activeElement.className") == "skip-link"
    page.keyboard.press("Enter")
    page.keyboard.press("Tab")
    focused = page.evaluate(
        "document.activeElement.tagName + (document.activeElement.id ? '#' + document.activeElement.id : '')"
    )
    assert focused == "SELECT#world", focused

    page.set_viewport_size({"width": 360, "height": 740})
    page.wait_for_function("document.documentElement.scrollWidth <= 360", timeout=5000)
    expect(page.get_by_role("button", name="Start run")).to_be_visible()
    dashboard.assert_no_console_errors()


def test_live_run_started_from_the_form(dashboard: Dashboard, service: Service, expect: Any, tmp_path: Path) -> None:
    page = dashboard.page
    dashboard.open()
    dashboard.hide_overlays()  # bare cells while waiting for black ones
    run_id = dashboard.start_run("room2", speed="20")
    start = dashboard.wait_state("s => s.pose !== null")["pose"]  # none until the first step

    def map_has_black_cells_and_robot_moved() -> bool:
        pose = dashboard.state()["pose"]
        moved = pose is not None and abs(pose["x"] - start["x"]) + abs(pose["y"] - start["y"]) > 0.1
        return moved and any(code == 1 for code in dashboard.sample_cells().values())

    wait_until(map_has_black_cells_and_robot_moved, 30, "black cells on the canvas and the robot to move")
    expect(page.locator("#conn")).to_have_attribute("data-state", "live")
    expect(page.locator("#stat-status")).to_have_text("running")
    assert re.fullmatch(r"\d+", page.locator("#stat-steps").inner_text())
    assert re.fullmatch(r"\d+\.\d %", page.locator("#stat-explored").inner_text())
    assert re.fullmatch(r"\d\.\d{3}", page.locator("#stat-f1").inner_text())

    # Change the speed of the running run (PATCH), then stop it.
    page.get_by_label("Speed", exact=True).select_option("50")
    page.get_by_role("button", name="Set speed").click()
    wait_until(lambda: service.api("GET", f"/api/runs/{run_id}").json()["speed"] == 50, 10, "the new speed")
    expect(page.locator("#stat-speed")).to_have_text("50\u00d7")
    page.get_by_role("button", name="Stop run").click()
    dashboard.wait_state("s => s.connection === 'ended'", 30)
    state = dashboard.state()
    assert state["status"] == "stopped"
    assert state["terminatedBy"] == "stopped"
    expect(page.locator("#stat-terminated")).to_have_text("stopped")
    expect(page.locator("#conn")).to_contain_text("stopped")

    # The robot is drawn where the page says it is (sampled behind its centre, away from the heading line).
    dashboard.show_layers(robot=True)
    page.wait_for_timeout(100)  # one animation frame
    pose = dashboard.state()["pose"]
    behind_m = 0.03
    pixel = dashboard.pixel_at_world(
        pose["x"] - behind_m * math.cos(pose["theta"]), pose["y"] - behind_m * math.sin(pose["theta"])
    )
    assert all(abs(a - b) < 40 for a, b in zip(pixel, ROBOT_ORANGE, strict=True)), pixel

    # The map the page built from snapshot + deltas is the service's map.csv, cell for cell.
    csv_text = service.api("GET", f"/api/runs/{run_id}/map.csv").text
    expected = parse_map_csv(csv_text)
    assert page.evaluate("window.sonarslam.cells()") == expected
    assert_canvas_shows(dashboard, expected)

    # The page's download link gives the same file.
    with page.expect_download() as info:
        page.get_by_role("link", name="Map CSV").click()
    saved = tmp_path / "map.csv"
    info.value.save_as(saved)
    assert saved.read_text() == csv_text
    dashboard.assert_no_console_errors()


def test_opening_a_finished_run_shows_its_final_map(dashboard: Dashboard, service: Service, expect: Any) -> None:
    run_id = finished_run(service, seed=1)
    expected = parse_map_csv(service.api("GET", f"/api/runs/{run_id}/map.csv").text)
    page = dashboard.page
    dashboard.open()
    page.get_by_role("button", name=re.compile(f"Open run .*{run_id}")).click()
    dashboard.wait_state("s => s.connection === 'ended'")
    assert dashboard.state()["status"] == "finished"
    expect(page.locator("#stat-terminated")).not_to_have_text("\u2013")
    assert page.evaluate("window.sonarslam.cells()") == expected
    assert_canvas_shows(dashboard, expected)

    # The truth overlay tints the cells; turning it off restores them.
    truth = page.get_by_label("Truth")
    expect(truth).to_be_enabled()
    truth.check()
    page.wait_for_timeout(100)
    tinted = dashboard.sample_cells()
    assert any(code is None for code in tinted.values())
    truth.uncheck()
    assert_canvas_shows(dashboard, expected)
    dashboard.assert_no_console_errors()


def test_zoom_and_pan_by_keyboard_wheel_and_drag(dashboard: Dashboard, service: Service) -> None:
    run_id = finished_run(service, seed=2)
    page = dashboard.page
    dashboard.open(f"#run={run_id}")
    dashboard.wait_state("s => s.connection === 'ended'")

    def cell(r: int, c: int) -> tuple[float, float]:
        p = page.evaluate("([r, c]) => window.sonarslam.cellToClient(r, c)", [r, c])
        return p["x"], p["y"]

    def pitch() -> float:
        return cell(0, 1)[0] - cell(0, 0)[0]

    fitted = pitch()
    page.locator("#map").focus()
    page.keyboard.press("+")
    assert pitch() == pytest.approx(fitted * 1.25, rel=1e-3)
    page.keyboard.press("-")
    assert pitch() == pytest.approx(fitted, rel=1e-3)
    x0, y0 = cell(0, 0)
    page.keyboard.press("ArrowLeft")
    page.keyboard.press("ArrowUp")
    x1, y1 = cell(0, 0)
    assert x1 > x0 and y1 > y0
    page.keyboard.press("0")
    assert cell(0, 0) == pytest.approx((x0, y0))

    box = page.locator("#map").bounding_box()
    assert box is not None
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(cx, cy)
    page.mouse.wheel(0, -300)
    page.wait_for_function(
        f"window.sonarslam.cellToClient(0, 1).x - window.sonarslam.cellToClient(0, 0).x > {fitted * 1.2}"
    )
    before = cell(0, 0)
    page.mouse.down()
    page.mouse.move(cx + 60, cy + 40, steps=4)
    page.mouse.up()
    after = cell(0, 0)
    assert after[0] - before[0] == pytest.approx(60, abs=1) and after[1] - before[1] == pytest.approx(40, abs=1)
    page.get_by_role("button", name="Fit").click()
    assert pitch() == pytest.approx(fitted, rel=1e-3)
    dashboard.assert_no_console_errors()


TINY_WORLD = b"""\
name = "tiny-box"
description = "a 2 x 1.6 m box with one pillar"
boundary = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.6], [0.0, 1.6]]

[start]
x = 0.5
y = 0.5
theta_deg = 0.0

[[obstacles]]
shape = "circle"
center = [1.4, 1.0]
radius = 0.15
"""


def test_uploaded_world_can_be_chosen_and_run(dashboard: Dashboard, service: Service, expect: Any) -> None:
    page = dashboard.page
    dashboard.open()
    page.get_by_label("Add a world (TOML file)").set_input_files(
        files=[{"name": "tiny-box.toml", "mimeType": "text/plain", "buffer": TINY_WORLD}]
    )
    page.get_by_role("button", name="Upload world").click()
    expect(page.locator("#upload-message")).to_have_text("Added world tiny-box.")
    world = page.get_by_label("World", exact=True)
    expect(world).to_have_value("tiny-box")
    expect(page.locator("#world optgroup[label='Uploaded'] option")).to_have_text(re.compile("^tiny-box"))

    run_id = dashboard.start_run("tiny-box", speed="max")
    state = dashboard.wait_state("s => s.connection === 'ended'", 60)
    assert state["grid"]["rows"] == 8 and state["grid"]["cols"] == 10
    expected = parse_map_csv(service.api("GET", f"/api/runs/{run_id}/map.csv").text)
    assert page.evaluate("window.sonarslam.cells()") == expected

    # The same world walked cell by cell, as the paper's robot does, instead of ending once mapped.
    mapped = service.api("GET", f"/api/runs/{run_id}").json()
    assert mapped["end_when_mapped"] is True
    full_walk = page.get_by_role("checkbox", name=re.compile("^Walk every cell"))
    expect(full_walk).not_to_be_checked()
    full_walk.check()
    walked_id = dashboard.start_run("tiny-box", speed="max")
    dashboard.wait_state("s => s.connection === 'ended'", 60)
    walked = service.api("GET", f"/api/runs/{walked_id}").json()
    assert walked["end_when_mapped"] is False and walked["terminated_by"] == "complete"
    assert walked["progress"]["step"] > mapped["progress"]["step"]

    # A bad file is refused with the service's reason, shown next to the form.
    page.get_by_label("Add a world (TOML file)").set_input_files(
        files=[{"name": "bad.toml", "mimeType": "text/plain", "buffer": b'name = "bad"\n'}]
    )
    dashboard.console.allow.append(lambda text: "status of 422" in text)
    page.get_by_role("button", name="Upload world").click()
    expect(page.locator("#upload-message")).to_contain_text("Could not add the world")
    dashboard.console.allow.clear()
    dashboard.assert_no_console_errors()
