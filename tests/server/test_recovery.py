"""Crash recovery: ``kill -9`` the service mid-run, restart it on the same data directory, lose nothing finished."""

from __future__ import annotations

import io
import os
import signal
import time
import zipfile
from pathlib import Path

import httpx
import numpy as np
from live_client import csv_codes, run_async, wait_for, watch
from service_process import serve_process

from robot.sensorlog import read_sensor_log


def test_kill_9_mid_run_then_restart(tmp_path: Path) -> None:
    data = tmp_path / "data"
    with serve_process(data, checkpoint_interval_s="0.3") as (proc, url), httpx.Client(base_url=url, timeout=30) as api:
        done_id = api.post("/api/runs", json={"world": "room2", "speed": "max", "max_steps": 25}).json()["id"]
        wait_for(lambda: api.get(f"/api/runs/{done_id}").json()["status"] == "finished")
        before = api.get(f"/api/runs/{done_id}").json()
        before_files = {n: api.get(f"/api/runs/{done_id}/{n}").content for n in ("map.csv", "trajectory.csv")}

        live_id = api.post("/api/runs", json={"world": "room1", "speed": 30.0, "max_steps": 5000}).json()["id"]
        wait_for(lambda: api.get(f"/api/runs/{live_id}").json()["progress"]["step"] >= 8)
        time.sleep(1.0)  # a few checkpoints (every 0.3 s)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)

    restarted = serve_process(data, checkpoint_interval_s="0.3")
    with restarted as (_proc, url), httpx.Client(base_url=url, timeout=30) as api:
        after = api.get(f"/api/runs/{done_id}").json()
        for key in ("status", "terminated_by", "metrics", "progress", "ended_at", "wall_time_s"):
            assert after[key] == before[key], key
        for name, content in before_files.items():
            assert api.get(f"/api/runs/{done_id}/{name}").content == content, name

        run = api.get(f"/api/runs/{live_id}").json()
        assert run["status"] == "interrupted" and run["terminated_by"] == "interrupted"
        assert run["progress"]["step"] >= 5  # the last checkpoint's progress
        assert set(run["metrics"]) >= {"f1", "cell_errors"}  # scored from the checkpoint
        checkpoint = csv_codes(api.get(f"/api/runs/{live_id}/map.csv").text)
        assert (checkpoint == 0).sum() > 5  # the partial map survived
        log = api.get(f"/api/runs/{live_id}/sensors.log")
        assert log.status_code == 200 and log.text.endswith("\n")
        log_file = tmp_path / "interrupted.log"
        log_file.write_bytes(log.content)
        _meta, records = read_sensor_log(log_file)
        assert sum(1 for r in records if r.kind == "S") >= 5  # every record reads back
        with zipfile.ZipFile(io.BytesIO(api.get(f"/api/runs/{live_id}/bundle.zip").content)) as zf:
            assert f"{live_id}/map.csv" in zf.namelist()

        viewer = run_async(watch(url.replace("http", "ws") + f"/ws/runs/{live_id}", timeout_s=20))
        assert viewer.final_status is not None and viewer.final_status["event"] == "interrupted"
        assert viewer.close_code == 1000 and viewer.grid is not None
        assert np.array_equal(viewer.grid, checkpoint)

        again = api.post("/api/runs", json={"world": "room2", "speed": "max", "max_steps": 5}).json()
        assert again["id"] not in (done_id, live_id)  # ids are never reused
