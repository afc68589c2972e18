"""A real uvicorn serving ``create_app(settings)`` on an ephemeral 127.0.0.1 port, on a thread."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import uvicorn
from fastapi import FastAPI
from pydantic_settings import BaseSettings, PydanticBaseSettingsSource

from server.main import Server, create_app
from server.runs import RunManager
from server.settings import ServerSettings

START_TIMEOUT_S = 15.0


class LiveServer:
    """``create_app(settings)`` served by uvicorn on a thread, as ``sonarslam serve`` would serve it."""

    def __init__(self, settings: ServerSettings, small_buffers: bool = False) -> None:
        self.settings = settings
        self.app: FastAPI = create_app(settings)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if small_buffers:
            # Accepted connections inherit this: a viewer that does not read soon blocks the server's writes.
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(64)
        self.port = self.sock.getsockname()[1]
        config = uvicorn.Config(
            self.app, log_level="warning", lifespan="on", ws_per_message_deflate=False, timeout_graceful_shutdown=5
        )
        self.server = Server(config, self.app)
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    @property
    def manager(self) -> RunManager:
        manager: RunManager = self.app.state.manager
        return manager

    def start(self) -> LiveServer:
        self.thread.start()
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the test server did not start")
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(30)
        self.sock.close()

    def client(self, token: str | None = None) -> httpx.Client:
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        return httpx.Client(base_url=self.url, headers=headers, timeout=30.0)


class IsolatedSettings(ServerSettings):
    """Settings from arguments only: nothing from the environment or config/server.toml leaks into a test."""

    @classmethod
    def settings_customise_sources(
        cls, settings_cls: type[BaseSettings], init_settings: PydanticBaseSettingsSource, **others: Any
    ) -> tuple[PydanticBaseSettingsSource, ...]:
        return (init_settings,)


def isolated_settings(data_dir: Path, **overrides: Any) -> ServerSettings:
    values: dict[str, Any] = {
        "host": "127.0.0.1",
        "port": 0,
        "data_dir": data_dir,
        "checkpoint_interval_s": 0.5,
        "max_concurrent_runs": 2,
        "web_dir": data_dir / "no-web",
    }
    values.update(overrides)
    return IsolatedSettings(**values)
