"""The REST API: worlds, configuration, runs, downloads, and a 4xx naming the field for every bad input."""

from __future__ import annotations

import io
import time
import zipfile
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from live_client import csv_codes, run_async, wait_ended, watch
from live_server import LiveServer

from robot.errors import HardwareError
from robot.replay import replay_path
from robot.sensorlog import read_sensor_log

FAST = {"world": "room2", "speed": "max", "max_steps": 40}
TINY_WORLD = """
name = "tiny"
description = "a 2 x 2 m box"
boundary = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]
[start]
x = 1.0
y = 0.5
theta_deg = 90.0
[[obstacles]]
shape = "circle"
center = [1.0, 1.4]
radius = 0.2
"""


def field_of(response: httpx.Response) -> list[Any]:
    """The location of the (first) field at fault in a 422 body."""
    detail = response.json()["detail"]
    assert isinstance(detail, list) and detail, response.text
    return list(detail[0]["loc"])


def test_health_and_the_page(api: httpx.Client) -> None:
    assert api.get("/api/health").json() == {"status": "ok"}
    page = api.get("/")
    assert page.status_code == 200 and "text/html" in page.headers["content-type"]
    assert api.get("/docs").status_code == 200
    assert "/api/runs" in api.get("/openapi.json").json()["paths"]


def test_the_page_is_served_from_web_dir(make_server: Any, tmp_path: Path) -> None:
    web = tmp_path / "web"
    (web / "js").mkdir(parents=True)
    (web / "index.html").write_text("<!doctype html><title>live</title>")
    (web / "js" / "app.js").write_text("export const x = 1;")
    server = make_server(web_dir=web)
    with server.client() as api:
        assert "<title>live</title>" in api.get("/").text
        assert api.get("/js/app.js").text.startswith("export")
        assert api.get("/js/missing.js").status_code == 404


def test_worlds_list_and_upload(api: httpx.Client) -> None:
    names = {w["name"]: w for w in api.get("/api/worlds").json()}
    assert {"room1", "room2", "room3", "room4"} <= set(names)
    assert names["room2"]["source"] == "builtin" and names["room2"]["width_m"] == 3.05

    created = api.post("/api/worlds", files={"file": ("tiny.toml", TINY_WORLD, "application/toml")})
    assert created.status_code == 201, created.text
    assert created.json()["name"] == "tiny" and created.json()["source"] == "uploaded"
    assert "tiny" in {w["name"] for w in api.get("/api/worlds").json()}

    run = api.post("/api/runs", json={**FAST, "world": "tiny"})
    assert run.status_code == 201, run.text
    ended = wait_ended(api, run.json()["id"])
    assert ended["status"] == "finished" and ended["grid"]["rows"] == 10


def test_a_world_whose_start_leaves_the_robot_in_a_wall_cannot_be_run(api: httpx.Client) -> None:
    # A valid world file, but the robot's body (6.4 cm radius) would overlap the wall at y = 0.
    squeezed = TINY_WORLD.replace('name = "tiny"', 'name = "squeezed"').replace("y = 0.5", "y = 0.03")
    assert api.post("/api/worlds", files={"file": ("s.toml", squeezed, "application/toml")}).status_code == 201
    run = api.post("/api/runs", json={**FAST, "world": "squeezed"})
    assert run.status_code == 422 and field_of(run) == ["body", "world"]
    assert "radius" in run.text


@pytest.mark.parametrize(
    ("content", "status", "needle"),
    [
        (TINY_WORLD.replace('shape = "circle"', 'shape = "blob"'), 422, "unknown shape"),
        (TINY_WORLD.replace("x = 1.0\n", "x = 1.0\nx = 2.0\n"), 422, "invalid TOML"),
        (TINY_WORLD.replace('name = "tiny"', 'name = "room1"'), 409, "built-in"),
        (TINY_WORLD.replace('name = "tiny"', 'name = "../evil"'), 422, "must match"),
        (b"\xff\xfe not text", 422, "UTF-8"),
        ("x" * 300_000, 413, "larger"),
    ],
)
def test_bad_world_uploads_are_refused(api: httpx.Client, content: str | bytes, status: int, needle: str) -> None:
    response = api.post("/api/worlds", files={"file": ("w.toml", content, "application/toml")})
    assert response.status_code == status, response.text
    assert needle in response.text


def test_config_is_validated_and_persisted(make_server: Any, tmp_path: Path) -> None:
    data = tmp_path / "persist"
    server = make_server(data_dir=data)
    with server.client() as api:
        defaults = api.get("/api/config").json()
        assert defaults["world"] == "room1" and defaults["resolution"] == 0.2 and defaults["mapper"] == "logodds"
        updated = api.put("/api/config", json={"world": "room2", "speed": "max", "seed": 7})
        assert updated.status_code == 200, updated.text
        assert updated.json()["world"] == "room2" and updated.json()["seed"] == 7
        assert updated.json()["resolution"] == defaults["resolution"]  # untouched fields stay

        bad = api.put("/api/config", json={"world": "nowhere"})
        assert bad.status_code == 422 and field_of(bad) == ["body", "world"]
        assert api.get("/api/config").json()["world"] == "room2"  # a refused update changes nothing

        run = api.post("/api/runs", json={"max_steps": 5}).json()  # the new defaults apply
        assert run["world"] == "room2" and run["seed"] == 7 and run["speed"] == "max"
        wait_ended(api, run["id"])
    server.stop()
    again = make_server(data_dir=data)
    with again.client() as api:
        assert api.get("/api/config").json()["seed"] == 7  # persisted across a restart


@pytest.mark.parametrize(
    ("body", "loc"),
    [
        ({"world": "atlantis"}, ["body", "world"]),
        ({"world": "../../etc/passwd"}, ["body", "world"]),
        ({"resolution": 0}, ["body", "resolution"]),
        ({"resolution": -0.2}, ["body", "resolution"]),
        ({"resolution": 1e9}, ["body", "resolution"]),
        ({"resolution": 0.001}, ["body", "resolution"]),
        ({"resolution": "fine"}, ["body", "resolution"]),
        ({"mapper": "magic"}, ["body", "mapper"]),
        ({"seed": -1}, ["body", "seed"]),
        ({"speed": 0}, ["body", "speed"]),
        ({"speed": "fast"}, ["body", "speed"]),
        ({"time_limit_s": -5}, ["body", "time_limit_s"]),
        ({"end_when_mapped": "sometimes"}, ["body", "end_when_mapped"]),
        ({"end_when_mapped": 1}, ["body", "end_when_mapped"]),
        ({"noise": {"range_noise_m": -1.0}}, ["body", "noise", "range_noise_m"]),
        ({"noise": {"no_such_noise": 1.0}}, ["body", "noise", "no_such_noise"]),
        ({"colour": "red"}, ["body", "colour"]),
    ],
)
def test_bad_run_options_name_the_field(api: httpx.Client, body: dict[str, Any], loc: list[Any]) -> None:
    response = api.post("/api/runs", json={**FAST, **body})
    assert response.status_code == 422, response.text
    assert field_of(response)[: len(loc)] == loc
    assert api.get("/api/runs").json() == []  # nothing was started


def test_malformed_and_oversized_bodies(api: httpx.Client) -> None:
    bad_json = api.post("/api/runs", content=b'{"world": "room2",', headers={"content-type": "application/json"})
    assert bad_json.status_code == 422 and field_of(bad_json)[0] == "body"
    not_object = api.post("/api/runs", json=["room2"])
    assert not_object.status_code == 422
    huge = api.post("/api/runs", content=b'{"world": "' + b"a" * (2 << 20) + b'"}',
                    headers={"content-type": "application/json"})  # fmt: skip
    assert huge.status_code == 413
    assert api.put("/api/config", content=b"\x00\x01", headers={"content-type": "application/json"}).status_code == 422


@pytest.mark.parametrize(
    "path",
    [
        "/api/runs/r-20990101-9999",
        "/api/runs/nonsense",
        "/api/runs/..%2F..%2Fsonarslam.db",
        "/api/runs/r-20990101-0001%2F..%2F..%2Fsonarslam.db/map.csv",
        "/api/runs/../../sonarslam.db",
        "/api/runs/%2e%2e/map.csv",
        "/api/runs/r-20990101-9999/map.csv",
        "/api/runs/r-20990101-9999/bundle.zip",
    ],
)
def test_unknown_and_traversing_run_ids_are_4xx(api: httpx.Client, path: str) -> None:
    response = api.get(path)
    assert 400 <= response.status_code < 500, (path, response.status_code)
    assert b"SQLite" not in response.content


def test_run_lifecycle_and_downloads(api: httpx.Client, tmp_path: Path) -> None:
    created = api.post("/api/runs", json={**FAST, "max_steps": 30, "seed": 3})
    assert created.status_code == 201
    run = created.json()
    run_id = run["id"]
    assert created.headers["location"] == f"/api/runs/{run_id}"
    assert run["world"] == "room2" and run["seed"] == 3 and run["grid"]["rows"] == 16
    ended = wait_ended(api, run_id)
    assert ended["status"] == "finished" and ended["terminated_by"] == "safety_cap"
    assert ended["progress"]["step"] == 30 and ended["progress"]["sim_time_s"] > 0
    assert 0 < ended["progress"]["explored"] <= 1 and ended["wall_time_s"] > 0
    assert [r["id"] for r in api.get("/api/runs").json()] == [run_id]

    files = {name: api.get(f"/api/runs/{run_id}/{name}") for name in ended["downloads"]}
    assert all(r.status_code == 200 for r in files.values()), {k: r.status_code for k, r in files.items()}
    grid = csv_codes(files["map.csv"].text)
    assert grid.shape == (16, 16)
    assert files["map.png"].content.startswith(b"\x89PNG")
    assert files["map.pgm"].content.startswith(b"P5\n16 16\n255\n")
    assert "image: map.pgm" in files["map.yaml"].text and "mode: trinary" in files["map.yaml"].text
    assert len(files["trajectory.csv"].text.splitlines()) == 1 + 1 + 30  # header, start, one row per step
    with zipfile.ZipFile(io.BytesIO(files["bundle.zip"].content)) as zf:
        names = {n.split("/", 1)[1] for n in zf.namelist()}
        assert {"map.csv", "map.png", "map.pgm", "map.yaml", "trajectory.csv", "sensors.log", "run.json"} <= names
        assert zf.read(f"{run_id}/map.csv") == files["map.csv"].content

    # The sensor log is in the replay format: replaying it rebuilds the same map.
    log_path = tmp_path / "sensors.log"
    log_path.write_bytes(files["sensors.log"].content)
    meta, records = read_sensor_log(log_path)
    assert meta["world"] == "room2" and sum(1 for r in records if r.kind == "S") >= 30
    replayed, _grid = replay_path(log_path).exported()
    assert np.array_equal(np.where(replayed < 0, 2, replayed), grid)

    assert api.delete(f"/api/runs/{run_id}").status_code == 204
    assert api.get(f"/api/runs/{run_id}").status_code == 404
    assert api.get(f"/api/runs/{run_id}/map.csv").status_code == 404
    assert api.delete(f"/api/runs/{run_id}").status_code == 404


def test_a_run_can_walk_every_cell_as_the_paper_does(api: httpx.Client) -> None:
    """By default a run ends once the map is done; ``end_when_mapped: false`` asks for the paper's full walk."""
    body = {"world": "room1", "speed": "max", "seed": 0}
    assert api.get("/api/config").json()["end_when_mapped"] is True
    mapped = wait_ended(api, api.post("/api/runs", json=body).json()["id"])
    walked = wait_ended(api, api.post("/api/runs", json={**body, "end_when_mapped": False}).json()["id"])
    assert mapped["end_when_mapped"] is True and walked["end_when_mapped"] is False
    assert mapped["terminated_by"] == walked["terminated_by"] == "complete"
    assert walked["progress"]["step"] > 2 * mapped["progress"]["step"]


def test_downloads_during_a_run_are_the_current_snapshot(api: httpx.Client) -> None:
    run_id = api.post("/api/runs", json={**FAST, "max_steps": 5000, "speed": 20.0}).json()["id"]
    deadline = time.monotonic() + 60
    while not (csv_codes(api.get(f"/api/runs/{run_id}/map.csv").text) == 0).any():  # the map grows as it runs
        assert time.monotonic() < deadline
        time.sleep(0.1)
    during = {name: api.get(f"/api/runs/{run_id}/{name}") for name in ("map.png", "sensors.log", "bundle.zip")}
    assert all(r.status_code == 200 for r in during.values())
    assert api.get(f"/api/runs/{run_id}").json()["status"] == "running"
    assert during["sensors.log"].text.startswith("# sonarslam-log 1")
    assert during["sensors.log"].text.endswith("\n")
    with zipfile.ZipFile(io.BytesIO(during["bundle.zip"].content)) as zf:
        assert f"{run_id}/map.csv" in zf.namelist() and f"{run_id}/run.json" in zf.namelist()

    patched = api.patch(f"/api/runs/{run_id}", json={"speed": "max"})
    assert patched.status_code == 200 and patched.json()["speed"] == "max"
    assert api.patch(f"/api/runs/{run_id}", json={"speed": -1}).status_code == 422
    assert api.patch(f"/api/runs/{run_id}", json={"speed": 2, "world": "room1"}).status_code == 422

    assert api.delete(f"/api/runs/{run_id}").status_code == 204  # stops it first
    assert api.get(f"/api/runs/{run_id}").status_code == 404


def test_runs_beyond_the_limit_wait_queued(make_server: Any) -> None:
    server: LiveServer = make_server(max_concurrent_runs=1, max_queued_runs=1)
    with server.client() as api:
        first = api.post("/api/runs", json={**FAST, "max_steps": 5000, "speed": 50.0}).json()
        second = api.post("/api/runs", json=FAST).json()
        assert second["status"] == "queued"
        third = api.post("/api/runs", json=FAST)
        assert third.status_code == 429
        stopped = api.post(f"/api/runs/{second['id']}/stop").json()  # a queued run can be stopped too
        assert stopped["status"] == "stopped"
        assert api.post(f"/api/runs/{first['id']}/stop").json()["status"] == "stopped"
        assert api.patch(f"/api/runs/{first['id']}", json={"speed": 2}).status_code == 409


def test_a_run_that_fails_ends_as_error_with_its_reason(make_server: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    import server.run_body as run_body

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise HardwareError("left motor driver not answering")

    monkeypatch.setattr(run_body, "open_hardware", broken)
    # On a thread of the service, as real hardware runs, where the patch reaches (a child process has its
    # own copy of the module; tests/server/test_engine_process.py fails runs there).
    server: LiveServer = make_server(sim_engine="thread")
    with server.client() as api:
        run_id = api.post("/api/runs", json=FAST).json()["id"]
        run = wait_ended(api, run_id)
        assert run["status"] == "error" and "left motor driver" in run["error"]
        assert api.get(f"/api/runs/{run_id}/map.csv").status_code == 200  # the (empty) map is still there
        viewer = run_async(watch(f"{server.ws_url}/ws/runs/{run_id}", timeout_s=20))
        assert viewer.final_status is not None and viewer.final_status["event"] == "error"
        assert "left motor driver" in viewer.final_status["message"]
