"""permessage-deflate on the live stream: off by default, offered with a setting, optional for the viewer.

These start ``sonarslam serve`` as its own process, so that what is checked is the path the real service
takes from its settings to uvicorn, not a test server configured by hand."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any, Literal

import httpx
import numpy as np
import pytest
from live_client import Viewer, csv_codes, run_async, wait_ended
from service_process import serve_process
from websockets.asyncio.client import connect
from websockets.extensions.permessage_deflate import PerMessageDeflate

from server.settings import ServerSettings, load_settings


async def watch_with(url: str, compression: Literal["deflate"] | None) -> tuple[Viewer, list[str]]:
    """A protocol-following viewer that offers permessage-deflate (websockets' default) or nothing;
    what it rebuilt, and the extensions the handshake settled on."""
    viewer = Viewer()
    async with asyncio.timeout(60), connect(url, max_size=None, compression=compression) as ws:
        extensions = [ext.name for ext in ws.protocol.extensions]
        assert all(isinstance(ext, PerMessageDeflate) for ext in ws.protocol.extensions)
        try:
            async for raw in ws:
                await viewer.handle(ws, raw)
        finally:
            viewer.close_code = ws.close_code
    return viewer, extensions


async def watch_both(url: str) -> list[tuple[Viewer, list[str]]]:
    return list(await asyncio.gather(watch_with(url, "deflate"), watch_with(url, None)))


def test_compression_is_off_by_default_and_can_be_turned_on(monkeypatch: pytest.MonkeyPatch) -> None:
    assert ServerSettings.model_fields["ws_compression"].default is False
    monkeypatch.setenv("SONARSLAM_WS_COMPRESSION", "true")
    assert load_settings().ws_compression is True


@pytest.mark.parametrize(("env_settings", "negotiated"), [({}, False), ({"ws_compression": "true"}, True)])
def test_viewers_with_and_without_deflate_rebuild_the_map(
    tmp_path: Path, env_settings: dict[str, str], negotiated: bool
) -> None:
    service = serve_process(tmp_path / "data", **env_settings)
    with service as (_proc, url), httpx.Client(base_url=url, timeout=30) as api:
        # 20x real time rather than max speed: both viewers join early and see it step by step.
        response = api.post("/api/runs", json={"world": "room2", "speed": 20.0, "max_steps": 40})
        assert response.status_code == 201, response.text
        run_id = response.json()["id"]
        (deflated, offered), (plain, not_offered) = run_async(
            watch_both(f"{url.replace('http', 'ws')}/ws/runs/{run_id}")
        )
        run: dict[str, Any] = wait_ended(api, run_id)
        expected = csv_codes(api.get(f"/api/runs/{run_id}/map.csv").text)

    assert run["status"] == "finished"
    # The viewer that offers compression gets it exactly when the service is set to offer it.
    assert offered == (["permessage-deflate"] if negotiated else [])
    assert not_offered == []  # and a viewer that does not offer it still gets plain frames
    for viewer in (deflated, plain):
        assert viewer.close_code == 1000 and viewer.final_status is not None
        assert viewer.final_status["event"] == "finished"
        assert viewer.steps > 0 and viewer.resyncs == 0  # it applied deltas, not only a final snapshot
        assert viewer.grid is not None and viewer.grid.shape == expected.shape
        assert np.array_equal(viewer.grid, expected), f"{int((viewer.grid != expected).sum())} cells differ"
    assert deflated.seq == plain.seq and np.array_equal(deflated.grid, plain.grid)
