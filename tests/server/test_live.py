"""The live map over WebSocket: viewers rebuild the grid from a snapshot and deltas, and it equals map.csv."""

from __future__ import annotations

import asyncio
import json
import socket
from typing import Any

import httpx
import numpy as np
from live_client import GREY, TERMINAL, Viewer, csv_codes, decode_cells, run_async, wait_ended, watch
from live_server import LiveServer
from numpy.typing import NDArray
from websockets.asyncio.client import connect

from server.broadcast import TRAIL_TOLERANCE_MM

FAST = {"world": "room2", "speed": "max", "max_steps": 60}


def start_run(api: httpx.Client, **options: Any) -> str:
    response = api.post("/api/runs", json={**FAST, **options})
    assert response.status_code == 201, response.text
    body = response.json()
    assert body["status"] in ("queued", "running")
    return str(body["id"])


def map_codes(api: httpx.Client, run_id: str) -> np.ndarray:
    response = api.get(f"/api/runs/{run_id}/map.csv")
    assert response.status_code == 200
    return csv_codes(response.text)


def assert_same_map(viewer: Viewer, api: httpx.Client, run_id: str) -> None:
    assert viewer.grid is not None
    expected = map_codes(api, run_id)
    assert viewer.grid.shape == expected.shape
    diff = np.argwhere(viewer.grid != expected)
    assert diff.size == 0, f"{len(diff)} cells differ, first at {diff[:5].tolist()}"


LIVE_METRICS = ("f1", "precision", "recall", "error_ratio", "cell_errors")


def final_state(api: httpx.Client, run_id: str) -> dict[str, Any]:
    """An ended run as REST tells it: progress, metrics, the last pose and the last sonar sweep."""
    run = api.get(f"/api/runs/{run_id}").json()
    trajectory = api.get(f"/api/runs/{run_id}/trajectory.csv").text.strip().split("\n")
    _, x, y, theta = (float(v) for v in trajectory[-1].split(",")[:4])
    sweeps = [line for line in api.get(f"/api/runs/{run_id}/sensors.log").text.split("\n") if line.startswith("S ")]
    return {
        "progress": run["progress"],
        "metrics": run["metrics"],
        "pose": (x, y, theta),
        "sweep": [float(v) for v in sweeps[-1].split()[2:]],
    }


def assert_same_state(viewer: Viewer, api: httpx.Client, run_id: str) -> None:
    """The grid, pose, sweep, progress and scores a viewer rebuilt from snapshot + deltas are the run's
    final ones (to the protocol's rounding: mm, mrad, cm, scores to 4 decimals)."""
    assert_same_map(viewer, api, run_id)
    final = final_state(api, run_id)
    assert viewer.view["progress"] == final["progress"]
    if viewer.last_snapshot is not None and viewer.last_snapshot["run"]["status"] in TERMINAL:
        # A viewer that joined after the end: its snapshot holds the closing scores at full precision.
        assert viewer.view["metrics"] == final["metrics"]
    else:
        live_metrics = {k: round(v, 4) if isinstance(v, float) else v for k, v in final["metrics"].items()}
        assert viewer.view["metrics"] == {k: live_metrics[k] for k in LIVE_METRICS}
    pose = viewer.view["pose"]
    assert all(isinstance(v, int) for v in pose)
    assert np.allclose(np.array(pose) / 1000, final["pose"], rtol=0, atol=0.0006), (pose, final["pose"])
    assert viewer.last_snapshot is not None
    max_range_cm = round(viewer.last_snapshot["robot"]["max_range_m"] * 100)
    for cm, range_m in zip(viewer.view["sweep"], final["sweep"], strict=True):
        if range_m >= max_range_cm / 100:
            assert cm == max_range_cm  # no echo
        else:
            assert cm < max_range_cm and abs(cm / 100 - range_m) <= 0.005 + 1e-9, (cm, range_m)


def test_one_viewer_rebuilds_the_map_cell_for_cell(server: LiveServer, api: httpx.Client) -> None:
    run_id = start_run(api)
    viewer = run_async(watch(f"{server.ws_url}/ws/runs/{run_id}"))

    assert viewer.hello is not None and viewer.hello["run_id"] == run_id and viewer.hello["protocol"] == 2
    assert viewer.close_code == 1000
    final = viewer.final_status
    assert final is not None and final["event"] == "finished" and final["terminated_by"] == "safety_cap"
    assert viewer.snapshots == 1 and viewer.resyncs == 0
    assert viewer.seq == final["seq"] == 60  # one step message per engine step, with consecutive seq
    assert_same_state(viewer, api, run_id)
    assert (viewer.grid == 0).any() and (viewer.grid == 1).any()  # it really mapped something

    snap = viewer.last_snapshot
    assert snap is not None
    assert snap["grid"] == {"rows": 16, "cols": 16, "resolution": 0.2, "origin": [0.0, 0.0]}
    truth = decode_cells(snap["truth"], 16, 16)
    assert set(np.unique(truth)) <= {0, 1, GREY}
    assert len(snap["robot"]["sonars"]) == 8

    run = api.get(f"/api/runs/{run_id}").json()
    assert run["status"] == "finished" and run["terminated_by"] == "safety_cap"
    assert set(run["metrics"]) >= {"f1", "precision", "recall", "error_ratio", "cell_errors"}
    assert run["progress"]["step"] == 60


def test_several_viewers_all_rebuild_the_same_map(server: LiveServer, api: httpx.Client) -> None:
    run_id = start_run(api, max_steps=150)
    url = f"{server.ws_url}/ws/runs/{run_id}"

    async def late_viewer() -> Viewer:
        await asyncio.sleep(0.5)
        return await watch(url)

    async def all_viewers() -> list[Viewer]:
        return list(await asyncio.gather(watch(url), watch(url), watch(url), late_viewer()))

    viewers = run_async(all_viewers())
    for viewer in viewers:
        assert viewer.close_code == 1000
        assert viewer.final_status is not None and viewer.final_status["event"] == "finished"
        assert viewer.seq == viewer.final_status["seq"]
        assert_same_map(viewer, api, run_id)
    sessions = {v.hello["session"] for v in viewers if v.hello}
    assert len(sessions) == 1


def dedup(points: list[list[int]]) -> NDArray[np.int64]:
    """A trail without repeated consecutive points (a step that did not move the robot adds one)."""
    a = np.asarray(points, dtype=np.int64).reshape(-1, 2)
    keep = np.ones(len(a), dtype=bool)
    keep[1:] = np.abs(np.diff(a, axis=0)).max(axis=1) > 1  # within a millimetre's rounding: the same
    return a[keep]


def path_distance_mm(points: NDArray[np.int64], path: NDArray[np.int64]) -> NDArray[np.float64]:
    """How far each point lies from the polyline ``path`` [mm]."""
    a, b = path[:-1, None, :].astype(float), path[1:, None, :].astype(float)
    d = b - a
    t = np.clip(((points[None] - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-9), 0.0, 1.0)
    return np.hypot(*np.moveaxis(points[None] - (a + t[..., None] * d), -1, 0)).min(axis=0)


def test_merged_steps_and_viewers_that_join_or_resync_late_all_end_with_the_final_state(
    make_server: Any,
) -> None:
    server: LiveServer = make_server(ws_max_rate_hz=20)  # a max-speed run: most steps go out merged
    with server.client() as api:
        # Room3 is not mapped before step 250 (room1 can be, and end before the late viewer joins).
        run_id = start_run(api, world="room3", max_steps=250)
        url = f"{server.ws_url}/ws/runs/{run_id}"

        async def resync_at_step_40(viewer: Viewer, msg: dict[str, Any], ws: Any) -> None:
            if msg["type"] == "step" and msg["seq"] >= 40 and viewer.snapshots == 1 and not viewer.waiting_for_snapshot:
                viewer.waiting_for_snapshot = True
                await ws.send(json.dumps({"type": "resync"}))

        async def late(delay_s: float) -> Viewer:
            await asyncio.sleep(delay_s)
            return await watch(url)

        async def all_viewers() -> list[Viewer]:
            return list(
                await asyncio.gather(
                    watch(url), watch(url, read_delay_s=0.03), watch(url, on_message=resync_at_step_40), late(0.4)
                )
            )

        viewers = run_async(all_viewers())
        assert wait_ended(api, run_id)["status"] == "finished"
        for viewer in viewers:
            assert viewer.close_code == 1000 and viewer.resyncs == 0
            assert viewer.final_status is not None and viewer.seq == viewer.final_status["seq"]
            assert_same_state(viewer, api, run_id)
        assert all(v.merged_steps > 0 for v in viewers)
        assert viewers[2].snapshots == 2
        # Target and action have no REST counterpart: every viewer agrees with the ended run's snapshot.
        after = run_async(watch(url, timeout_s=20))
        assert after.steps == 0
        for viewer in viewers:
            assert viewer.view["target"] == after.view["target"]
            assert viewer.view["action"] == after.view["action"] is not None
            assert np.abs(np.array(viewer.view["pose"]) - after.view["pose"]).max() <= 1
            assert viewer.view["sweep"] == after.view["sweep"]
            # Merged steps carry the corners of the path they skipped: the drawn path is the run's
            # whole path, within the trail tolerance, drawn through points the run really passed.
            ours, theirs = dedup(viewer.trail), dedup(after.last_snapshot["trail"])
            assert path_distance_mm(theirs, ours).max() <= TRAIL_TOLERANCE_MM + 1
            assert path_distance_mm(ours, theirs).max() <= 1


def test_steps_carry_only_what_changed_and_timing_only_on_request(make_server: Any) -> None:
    server: LiveServer = make_server(ws_max_rate_hz=10_000)  # every step on its own
    steps: dict[str, list[dict[str, Any]]] = {"plain": [], "timed": []}

    async def plain_step(viewer: Viewer, msg: dict[str, Any], ws: Any) -> None:
        if msg["type"] == "step":
            steps["plain"].append(msg)

    async def timed_step(viewer: Viewer, msg: dict[str, Any], ws: Any) -> None:
        if msg["type"] == "step":
            steps["timed"].append(msg)

    with server.client() as api:
        run_id = start_run(api, world="room3", max_steps=120)
        url = f"{server.ws_url}/ws/runs/{run_id}"

        async def both() -> list[Viewer]:
            return list(
                await asyncio.gather(watch(url, on_message=plain_step), watch(f"{url}?timing=1", on_message=timed_step))
            )

        viewers = run_async(both())
        for viewer in viewers:
            assert_same_state(viewer, api, run_id)
    plain, timed = steps["plain"], steps["timed"]
    for viewer, seen in zip(viewers, (plain, timed), strict=True):
        assert viewer.last_snapshot is not None  # the run may have begun before the viewer came
        assert sum(m.get("merged", 1) for m in seen) == 120 - viewer.last_snapshot["seq"]
    assert not any("wall_time" in m for m in plain)
    assert all(isinstance(m["wall_time"], float) for m in timed)
    assert len(viewers[1].latencies_s) == len(timed)
    # The scores change with the map, and only then (the first step brings those of the empty map).
    for m in plain:
        assert m["seq"] == 1 or (("metrics" in m) <= ("cells" in m) and ("explored" in m) <= ("cells" in m))
    assert 0 < sum("cells" in m for m in plain) < len(plain)
    assert 0 < sum("action" in m for m in plain) < len(plain) / 2
    assert all(set(m) >= {"type", "seq", "t_s", "pose"} for m in plain)  # the robot moves every step


def test_a_finished_run_sends_hello_snapshot_status_then_closes(server: LiveServer, api: httpx.Client) -> None:
    run_id = start_run(api, max_steps=20)
    wait_ended(api, run_id)
    viewer = run_async(watch(f"{server.ws_url}/ws/runs/{run_id}", timeout_s=20))
    assert viewer.snapshots == 1 and viewer.steps == 0
    assert [s["event"] for s in viewer.statuses] == ["finished"]
    assert viewer.close_code == 1000
    assert viewer.last_snapshot is not None and viewer.last_snapshot["run"]["status"] == "finished"
    assert len(viewer.last_snapshot["trail"]) == 20
    assert_same_state(viewer, api, run_id)  # the scores too: the closing ones, at full precision


def test_stop_mid_run_keeps_the_partial_map(server: LiveServer, api: httpx.Client) -> None:
    run_id = start_run(api, max_steps=5000, world="room1")
    stopped: dict[str, Any] = {}

    async def stop_after_some_steps(viewer: Viewer, msg: dict[str, Any], ws: Any) -> None:
        if msg["type"] == "step" and msg["seq"] >= 15 and not stopped:
            stopped["at"] = msg["seq"]
            async with httpx.AsyncClient(base_url=server.url, timeout=30) as client:
                stopped["response"] = await client.post(f"/api/runs/{run_id}/stop")

    viewer = run_async(watch(f"{server.ws_url}/ws/runs/{run_id}", on_message=stop_after_some_steps))

    response = stopped["response"]
    assert response.status_code == 200, response.text
    assert response.json()["status"] == "stopped" and response.json()["terminated_by"] == "stopped"
    assert viewer.final_status is not None and viewer.final_status["event"] == "stopped"
    assert viewer.close_code == 1000
    assert stopped["at"] <= viewer.seq == viewer.final_status["seq"] < 5000
    assert_same_state(viewer, api, run_id)
    assert viewer.view["action"] == "stop" and viewer.view["progress"]["step"] == viewer.seq - 1
    assert (viewer.grid == 0).sum() > 5  # the partial map is kept
    assert api.post(f"/api/runs/{run_id}/stop").status_code == 409  # already ended


def test_reconnect_mid_run_and_resync(server: LiveServer, api: httpx.Client) -> None:
    run_id = start_run(api, max_steps=200)
    url = f"{server.ws_url}/ws/runs/{run_id}"

    async def resync_once(viewer: Viewer, msg: dict[str, Any], ws: Any) -> None:
        if msg["type"] == "step" and viewer.steps == 5:
            viewer.waiting_for_snapshot = True  # as after a gap: ignore steps until the snapshot
            await ws.send(json.dumps({"type": "resync"}))

    async def scenario() -> tuple[Viewer, Viewer]:
        first = await watch(url, until=lambda v: v.seq >= 10)  # then the connection drops
        second = await watch(url, on_message=resync_once)
        return first, second

    first, second = run_async(scenario())

    assert first.hello is not None and second.hello is not None
    assert first.hello["session"] == second.hello["session"]  # same service: a reconnect, not a restart
    assert second.snapshots == 2  # the first on connecting, the second on request
    assert second.last_snapshot is not None and second.last_snapshot["seq"] >= 10
    assert second.close_code == 1000 and second.final_status is not None
    assert second.seq == second.final_status["seq"]
    assert_same_state(second, api, run_id)


def _raw_websocket(port: int, path: str) -> socket.socket:
    """A viewer that completes the handshake and then never reads a byte, with a tiny receive buffer."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
    sock.settimeout(10)
    sock.connect(("127.0.0.1", port))
    request = (
        f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    sock.sendall(request.encode())
    head = b""
    while b"\r\n\r\n" not in head:
        head += sock.recv(1)  # exactly the response head; nothing after it is ever read
    assert head.startswith(b"HTTP/1.1 101"), head
    return sock


BIG_HALL = """name = "bighall"
description = "a 12 x 12 m empty hall: a big grid, so that snapshots are large"
boundary = [[0.0, 0.0], [12.0, 0.0], [12.0, 12.0], [0.0, 12.0]]
[start]
x = 6.0
y = 6.0
theta_deg = 90.0
"""


def test_a_viewer_that_never_reads_does_not_stall_the_run(make_server: Any) -> None:
    server: LiveServer = make_server(small_buffers=True, ws_queue_size=8, ws_max_rate_hz=10_000)
    with server.client() as api:
        assert api.post("/api/worlds", files={"file": ("bighall.toml", BIG_HALL)}).status_code == 201
        run_id = start_run(api, world="bighall", resolution=0.1, max_steps=400)
        stuck = _raw_websocket(server.port, f"/ws/runs/{run_id}")  # never reads, stays connected throughout
        try:
            slow = run_async(_fall_behind_then_read(server, run_id))
        finally:
            stuck.close()
        run = wait_ended(api, run_id, timeout_s=5)
        assert run["status"] == "finished"
        assert slow.close_code == 1000
        assert slow.merged_steps >= 1 and slow.resyncs == 0  # it fell behind and got merged deltas
        assert slow.final_status is not None and slow.seq == slow.final_status["seq"]
        assert_same_map(slow, api, run_id)


async def _fall_behind_then_read(server: LiveServer, run_id: str) -> Viewer:
    """A viewer that stops reading: it asks for many snapshots to fill every buffer between it and the
    server, reads nothing until the run has ended, then reads everything it was sent."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 2048)
    sock.connect(("127.0.0.1", server.port))
    sock.setblocking(False)
    viewer = Viewer()
    url = f"{server.ws_url}/ws/runs/{run_id}"
    async with (
        asyncio.timeout(120),
        connect(url, sock=sock, max_size=None, max_queue=2, compression=None) as ws,
        httpx.AsyncClient(base_url=server.url, timeout=30) as client,
    ):
        while (await client.get(f"/api/runs/{run_id}")).json()["progress"]["step"] < 20:
            await asyncio.sleep(0.02)
        for _ in range(40):  # each answer is a snapshot of about 40 kB: together more than every buffer holds
            await ws.send(json.dumps({"type": "resync"}))
            await asyncio.sleep(0.01)
        while (await client.get(f"/api/runs/{run_id}")).json()["status"] == "running":
            await asyncio.sleep(0.05)
        async for raw in ws:
            await viewer.handle(ws, raw)
        viewer.close_code = ws.close_code
    return viewer
