"""Fixtures for the service: a real uvicorn on an ephemeral 127.0.0.1 port with its own data directory."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from live_server import LiveServer, isolated_settings


@pytest.fixture
def make_server(tmp_path: Path) -> Iterator[Callable[..., LiveServer]]:
    """``make_server(**settings)`` starts a server; every one started is stopped after the test."""
    started: list[LiveServer] = []

    def make(small_buffers: bool = False, data_dir: Path | None = None, **overrides: Any) -> LiveServer:
        settings = isolated_settings(data_dir or tmp_path / "data", **overrides)
        server = LiveServer(settings, small_buffers=small_buffers).start()
        started.append(server)
        return server

    yield make
    for server in started:
        server.stop()


@pytest.fixture
def server(make_server: Callable[..., LiveServer]) -> LiveServer:
    return make_server()


@pytest.fixture
def api(server: LiveServer) -> Iterator[httpx.Client]:
    with server.client() as client:
        yield client
