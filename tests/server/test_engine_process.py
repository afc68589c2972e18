"""Simulated runs' engines in child processes: a child that dies ends its run as ``error`` and the service
serves on; stop and speed orders reach the child; signals to the process group are the service's to act
on; a graceful shutdown interrupts the run, and a service killed with -9 takes its engines with it."""

from __future__ import annotations

import multiprocessing
import os
import shutil
import signal
import sqlite3
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
from live_client import Viewer, run_async, wait_ended, watch
from live_server import LiveServer
from service_process import serve_process

from server.engine_process import FrameReader, FrameWriter

FAST = {"world": "room2", "speed": "max", "max_steps": 40}
SLOW = {"world": "room1", "speed": 0.2, "max_steps": 5000}  # a fifth of real time: a step takes seconds


def eventually(predicate: Callable[[], Any], timeout_s: float = 60.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while not (value := predicate()):
        assert time.monotonic() < deadline, "condition not reached in time"
        time.sleep(0.02)
    return value


def engine_pid(server: LiveServer, run_id: str) -> int:
    def pid() -> int | None:
        session = server.manager.sessions.get(run_id)
        return session.child.pid if session is not None and session.child is not None else None

    found: int = eventually(pid)
    assert found != os.getpid()
    return found


def alive(pid: int) -> bool:
    """Running, as opposed to gone or a zombie that only waits to be reaped."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_killed_engine_ends_its_run_as_error_and_the_service_serves_on(server: LiveServer, api: httpx.Client
                                                                          ) -> None:  # fmt: skip
    run_id = api.post("/api/runs", json={"world": "room1", "speed": 20.0, "max_steps": 5000}).json()["id"]
    pid = engine_pid(server, run_id)

    async def kill_after_a_few_steps(viewer: Viewer, msg: dict[str, Any], _ws: Any) -> None:
        if msg["type"] == "step" and viewer.steps == 3:
            os.kill(pid, signal.SIGKILL)

    viewer = run_async(watch(f"{server.ws_url}/ws/runs/{run_id}", on_message=kill_after_a_few_steps))
    final = viewer.final_status
    assert final is not None and final["event"] == "error" and "killed by SIGKILL" in final["message"]
    run = wait_ended(api, run_id)
    assert run["status"] == "error" and run["terminated_by"] == "error"
    assert "engine process was killed by SIGKILL" in run["error"]
    assert set(run["metrics"]) >= {"f1", "cell_errors"}  # scored from its last checkpoint
    assert api.get(f"/api/runs/{run_id}/map.csv").status_code == 200
    assert api.get(f"/api/runs/{run_id}/sensors.log").text.endswith("\n")  # a cut record is dropped

    again = api.post("/api/runs", json=FAST).json()["id"]
    assert wait_ended(api, again)["status"] == "finished"


def test_an_engine_that_fails_ends_its_run_as_error_with_the_reason(make_server: Any) -> None:
    server: LiveServer = make_server(max_concurrent_runs=1)
    with server.client() as api:
        first = api.post("/api/runs", json=SLOW).json()["id"]
        second = api.post("/api/runs", json=FAST).json()["id"]
        shutil.rmtree(server.settings.data_dir / "runs" / second)  # its sensor log cannot be opened
        api.post(f"/api/runs/{first}/stop")
        run = wait_ended(api, second)
        assert run["status"] == "error" and run["error"].startswith("FileNotFoundError")
        assert "sensors.log" in run["error"]
        assert wait_ended(api, api.post("/api/runs", json=FAST).json()["id"])["status"] == "finished"


def test_speed_and_stop_orders_reach_the_engine(server: LiveServer, api: httpx.Client) -> None:
    run_id = api.post("/api/runs", json=SLOW).json()["id"]
    engine_pid(server, run_id)
    assert api.patch(f"/api/runs/{run_id}", json={"speed": "max"}).status_code == 200
    eventually(lambda: api.get(f"/api/runs/{run_id}").json()["progress"]["step"] >= 20)  # minutes at 0.2
    assert api.patch(f"/api/runs/{run_id}", json={"speed": 0.2}).status_code == 200
    stopped = api.post(f"/api/runs/{run_id}/stop").json()  # answers once the run has ended
    assert stopped["status"] == "stopped" and stopped["terminated_by"] == "stopped"


def test_the_engine_leaves_interrupt_and_terminate_signals_to_the_service(server: LiveServer, api: httpx.Client
                                                                         ) -> None:  # fmt: skip
    run_id = api.post("/api/runs", json={**FAST, "speed": 5.0}).json()["id"]
    pid = engine_pid(server, run_id)
    eventually(lambda: api.get(f"/api/runs/{run_id}").json()["status"] == "running")
    os.kill(pid, signal.SIGINT)  # what Ctrl-C in a terminal, or systemd stopping the service, sends them all
    os.kill(pid, signal.SIGTERM)
    api.patch(f"/api/runs/{run_id}", json={"speed": "max"})
    assert wait_ended(api, run_id)["status"] == "finished"


def test_shutting_the_service_down_interrupts_its_runs(make_server: Any, tmp_path: Path) -> None:
    server: LiveServer = make_server()
    with server.client() as api:
        run_id = api.post("/api/runs", json=SLOW).json()["id"]
        pid = engine_pid(server, run_id)
        eventually(lambda: api.get(f"/api/runs/{run_id}").json()["status"] == "running")
    server.stop()
    eventually(lambda: not alive(pid), timeout_s=10)
    with sqlite3.connect(server.settings.data_dir / "sonarslam.db") as db:
        row = db.execute("SELECT status, terminated_by FROM runs WHERE id = ?", (run_id,)).fetchone()
    assert row == ("interrupted", "shutdown")


def children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError):
                continue
            if parent == pid:
                found.append(int(entry.name))
    return found


def test_a_service_killed_with_9_leaves_its_run_to_recovery(tmp_path: Path) -> None:
    data = tmp_path / "data"
    with serve_process(data, checkpoint_interval_s="0.3") as (proc, url), httpx.Client(base_url=url) as api:
        run_id = api.post("/api/runs", json={"world": "room1", "speed": 30.0, "max_steps": 5000}).json()["id"]
        eventually(lambda: api.get(f"/api/runs/{run_id}").json()["progress"]["step"] >= 3)
        engines = eventually(lambda: [e for child in children(proc.pid) for e in children(child)])
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        eventually(lambda: not any(alive(pid) for pid in engines), timeout_s=10)  # gone with the service
    with sqlite3.connect(data / "sonarslam.db") as db:
        status = db.execute("SELECT status FROM runs WHERE id = ?", (run_id,)).fetchone()[0]
    assert status == "running"  # as the service left it: the next start recovers it as interrupted


def test_steps_wait_in_order_while_the_parent_falls_behind() -> None:
    """The child's messages never block it: what the pipe cannot take waits, and arrives in order."""
    parent, child = multiprocessing.Pipe(duplex=False)
    writer = FrameWriter(child)
    sent = [("step", i, "x" * 1000) for i in range(500)]  # 0.5 MB: several times what a pipe holds
    for message in sent:
        writer.send(message)  # the parent reads nothing yet: this returns all the same
    reader = FrameReader()
    received: list[Any] = []
    while len(received) < len(sent):
        received += reader.feed(os.read(parent.fileno(), 1 << 16))  # a flusher thread writes as room appears
    writer.close()
    assert received == sent
    assert os.read(parent.fileno(), 1) == b""  # then end-of-file
