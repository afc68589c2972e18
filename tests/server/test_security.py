"""Security: bearer tokens on control endpoints, token-only viewing, closed CORS, loopback by default."""

from __future__ import annotations

import subprocess
import sys
from typing import Any

import httpx
import pytest
from live_client import run_async, wait_for, watch
from live_server import LiveServer, isolated_settings
from pydantic import SecretStr
from websockets.exceptions import InvalidStatus

from robot.errors import ConfigError
from server.main import urls
from server.settings import load_settings, with_token

TOKEN = "s3cret-token-for-tests"
FAST = {"world": "room2", "speed": "max", "max_steps": 10}
TINY_WORLD = b"""name = "box"
boundary = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]]
[start]
x = 1.0
y = 1.0
theta_deg = 0.0
"""


def control_requests(client: httpx.Client, run_id: str) -> dict[str, httpx.Response]:
    return {
        "start": client.post("/api/runs", json=FAST),
        "configure": client.put("/api/config", json={"seed": 1}),
        "upload": client.post("/api/worlds", files={"file": ("box.toml", TINY_WORLD)}),
        "speed": client.patch(f"/api/runs/{run_id}", json={"speed": 2}),
        "stop": client.post(f"/api/runs/{run_id}/stop"),
        "delete": client.delete(f"/api/runs/{run_id}"),
    }


def test_control_endpoints_refuse_requests_without_the_token(make_server: Any) -> None:
    server: LiveServer = make_server(token=TOKEN)
    with server.client(TOKEN) as owner:
        # A slow run, so that it is still running when the owner changes its speed and stops it.
        run_id = owner.post("/api/runs", json={**FAST, "speed": 10.0, "max_steps": 5000}).json()["id"]
        for who in (server.client(), server.client("wrong-token-123")):
            with who:
                for name, response in control_requests(who, run_id).items():
                    assert response.status_code == 401, (name, response.status_code, response.text)
                    assert response.headers["www-authenticate"] == "Bearer"
                # Viewing stays open unless configured otherwise.
                assert who.get("/api/runs").status_code == 200
                assert who.get(f"/api/runs/{run_id}/map.csv").status_code == 200
        # Nobody stopped it. On a busy machine the engine's first child process can take over a
        # second to start, so wait until the run has left the queue; then it must be running.
        wait_for(lambda: owner.get(f"/api/runs/{run_id}").json()["status"] != "queued", timeout_s=30)
        assert owner.get(f"/api/runs/{run_id}").json()["status"] == "running"
        # Only the header counts for control: a token in the query string is not enough.
        assert server.client().post(f"/api/runs/{run_id}/stop?token={TOKEN}").status_code == 401
        allowed = control_requests(owner, run_id)
        assert {k: r.status_code for k, r in allowed.items()} == {
            "start": 201,
            "configure": 200,
            "upload": 201,
            "speed": 200,
            "stop": 200,
            "delete": 204,
        }


def test_token_only_viewing(make_server: Any) -> None:
    server: LiveServer = make_server(token=TOKEN, view_access="token")
    with server.client(TOKEN) as owner:
        run_id = owner.post("/api/runs", json=FAST).json()["id"]
    with server.client() as anonymous:
        assert anonymous.get("/api/health").status_code == 200  # liveness stays open
        assert anonymous.get("/api/runs").status_code == 401
        assert anonymous.get(f"/api/runs/{run_id}/map.csv").status_code == 401
        assert anonymous.get(f"/api/runs/{run_id}/map.csv?token={TOKEN}").status_code == 200  # <a href> downloads
    url = f"{server.ws_url}/ws/runs/{run_id}"
    with pytest.raises(InvalidStatus) as refused:
        run_async(watch(url, timeout_s=10))
    assert refused.value.response.status_code == 401
    viewer = run_async(watch(f"{url}?token={TOKEN}", timeout_s=30))
    assert viewer.close_code == 1000 and viewer.final_status is not None


def test_unknown_run_websocket_is_refused_with_404(server: LiveServer) -> None:
    for run_id in ("r-20990101-0001", "..%2F..%2Fetc", "nonsense"):
        with pytest.raises(InvalidStatus) as refused:
            run_async(watch(f"{server.ws_url}/ws/runs/{run_id}", timeout_s=10))
        assert refused.value.response.status_code in (403, 404)


def test_cors_is_closed_by_default(api: httpx.Client) -> None:
    response = api.get("/api/runs", headers={"Origin": "https://evil.example"})
    assert "access-control-allow-origin" not in response.headers
    preflight = api.options(
        "/api/runs", headers={"Origin": "https://evil.example", "Access-Control-Request-Method": "POST"}
    )
    assert "access-control-allow-origin" not in preflight.headers


def test_cors_opens_only_for_configured_origins(make_server: Any) -> None:
    server: LiveServer = make_server(cors_origins=("https://lab.example",))
    with server.client() as api:
        ok = api.get("/api/runs", headers={"Origin": "https://lab.example"})
        assert ok.headers["access-control-allow-origin"] == "https://lab.example"
        other = api.get("/api/runs", headers={"Origin": "https://evil.example"})
        assert "access-control-allow-origin" not in other.headers


def test_binding_beyond_loopback_generates_a_token(tmp_path: Any) -> None:
    local = isolated_settings(tmp_path)
    assert local.loopback_only and not local.token_required
    assert with_token(local) == (local, False)
    wide = isolated_settings(tmp_path, host="0.0.0.0")
    assert wide.token_required
    settings, generated = with_token(wide)
    assert generated and settings.token is not None and len(settings.token.get_secret_value()) >= 24
    configured = isolated_settings(tmp_path, host="0.0.0.0", token=SecretStr(TOKEN))
    assert with_token(configured) == (configured, False)
    assert urls(wide, 8000)[0] == "http://127.0.0.1:8000/"


def test_bad_settings_fail_at_start_up_with_one_line(tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SONARSLAM_MAX_CONCURRENT_RUNS", "zero")
    with pytest.raises(ConfigError, match="max_concurrent_runs"):
        load_settings()
    monkeypatch.delenv("SONARSLAM_MAX_CONCURRENT_RUNS")
    with pytest.raises(ConfigError, match="token") as short:
        load_settings(token="abc")
    assert "abc" not in str(short.value)  # a secret is never echoed
    result = subprocess.run(
        [sys.executable, "-m", "robot", "serve", "--port", "70000", "--data-dir", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "port" in result.stderr and "Traceback" not in result.stderr


def test_tokens_in_query_strings_are_redacted_from_the_log() -> None:
    import logging

    from server.main import RedactTokens

    record = logging.LogRecord(
        "uvicorn.access",
        logging.INFO,
        __file__,
        1,
        '%s - "%s %s HTTP/%s" %d',
        ("127.0.0.1:5000", "GET", "/ws/runs/r-1?token=s3cret-token&x=1", "1.1", 200),
        None,
    )
    RedactTokens().filter(record)
    line = record.getMessage()
    assert "s3cret-token" not in line
    assert "token=[redacted]&x=1" in line
