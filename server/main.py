"""The service's entry points: ``create_app(settings)`` builds the app, ``serve(args)`` runs it with uvicorn."""

from __future__ import annotations

import argparse
import fcntl
import logging
import re
import signal
import socket
import sys
import uuid
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from types import FrameType
from typing import IO

import uvicorn
from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import FileResponse, HTMLResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.types import ASGIApp, Receive, Scope, Send

from robot import __version__
from robot.errors import ConfigError
from server.api.routes import config, health, runs, worlds, ws
from server.errors import install_error_handlers
from server.runs import RunManager
from server.settings import ServerSettings, load_settings, with_token
from server.store import RunStore
from server.worlds import WorldCatalog

log = logging.getLogger("sonarslam.server")

_TOKEN_IN_QUERY = re.compile(r"(token=)[^&\s\"']+")


class RedactTokens(logging.Filter):
    """Keep bearer tokens that arrive in a URL's query string (``?token=...``) out of the access log."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.args:
            record.args = tuple(
                _TOKEN_IN_QUERY.sub(r"\1[redacted]", a) if isinstance(a, str) else a for a in record.args
            )
        if isinstance(record.msg, str):
            record.msg = _TOKEN_IN_QUERY.sub(r"\1[redacted]", record.msg)
        return True


PLACEHOLDER_PAGE = """<!doctype html><meta charset="utf-8"><title>sonarslam</title>
<h1>sonarslam</h1><p>The live page is not installed (no <code>web/index.html</code>).
See the API at <a href="/docs">/docs</a>.</p>"""


def lock_data_dir(data_dir: Path) -> IO[str]:
    """Create the data directory and hold its lock: two services must not share one database."""
    try:
        data_dir.mkdir(parents=True, exist_ok=True)
        handle = open(data_dir / ".lock", "a+", encoding="utf-8")  # noqa: SIM115 - held for the app's life
    except OSError as exc:
        raise ConfigError(f"data directory {data_dir}: {exc.strerror or exc}") from None
    try:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        raise ConfigError(f"data directory {data_dir} is in use by another sonarslam service") from None
    return handle


def create_app(settings: ServerSettings) -> FastAPI:
    """The ASGI app. Nothing starts until its lifespan runs: then it opens the store and the run manager."""

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        lock = lock_data_dir(settings.data_dir)
        store = RunStore(settings.data_dir / "sonarslam.db")
        catalog = WorldCatalog(settings.data_dir / "worlds", settings.max_world_bytes)
        manager = RunManager(settings, store, catalog)
        app.state.manager = manager
        try:
            await manager.start()
            yield
        finally:
            await manager.shutdown()
            store.close()
            lock.close()

    app = FastAPI(
        title="sonarslam",
        version=__version__,
        summary="Sonar occupancy-grid SLAM: start simulated or real runs, watch them live, download their maps.",
        lifespan=lifespan,
        max_body_size=settings.max_body_bytes,
    )
    app.state.settings = settings
    app.state.session_id = uuid.uuid4().hex  # tells viewers that the service has restarted
    install_error_handlers(app)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["GET", "POST", "PUT", "PATCH", "DELETE"],
            allow_headers=["Authorization", "Content-Type"],
        )
    for module in (health, worlds, config, runs, ws):
        app.include_router(module.router)
    _mount_page(app, settings.web_dir)
    return app


def _mount_page(app: FastAPI, web_dir: Path) -> None:
    """The static page at ``/`` (written separately in ``web/``); a pointer to ``/docs`` until it exists."""

    @app.get("/", include_in_schema=False)
    async def index() -> Response:
        page = web_dir / "index.html"
        if page.is_file():
            return FileResponse(page, headers={"Cache-Control": "no-cache"})
        return HTMLResponse(PLACEHOLDER_PAGE)

    if web_dir.is_dir():
        app.mount("/", _HttpOnly(StaticFiles(directory=web_dir, html=True)), name="web")


class _HttpOnly:
    """Static files answer HTTP only; a WebSocket to an unknown path is refused rather than crashing."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 1008, "reason": "no such endpoint"})
            return
        await self.app(scope, receive, send)


class Server(uvicorn.Server):
    """uvicorn's server, except that SIGINT or SIGTERM also halts the robot's motors at once.

    uvicorn's graceful shutdown first waits up to ``timeout_graceful_shutdown`` for open connections
    (live viewers) and only then runs the lifespan that stops the runs; a robot must not drive on
    meanwhile. Only the main thread receives signals, so this runs on the event loop's thread.
    """

    def __init__(self, config: uvicorn.Config, app: FastAPI) -> None:
        super().__init__(config)
        self.service_app = app

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        try:
            manager: RunManager | None = getattr(self.service_app.state, "manager", None)
            if manager is not None:
                manager.halt_hardware(f"stopped by {signal.Signals(sig).name}")
        finally:
            super().handle_exit(sig, frame)  # shut down whatever happened above


def _listen(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise ConfigError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


def urls(settings: ServerSettings, port: int) -> list[str]:
    """The addresses to print: loopback first, then this machine's name when bound to every interface."""
    hosts = [settings.host]
    if settings.host in ("0.0.0.0", "::"):
        hosts = ["127.0.0.1", socket.gethostname()]
    shown = [f"[{h}]" if ":" in h else h for h in hosts]
    return [f"http://{h}:{port}/" for h in shown]


def serve(args: argparse.Namespace) -> int:
    """``sonarslam serve``: check the settings, bind, print where to look, and run until interrupted."""
    settings = load_settings(
        host=getattr(args, "host", None),
        port=getattr(args, "port", None),
        hardware=getattr(args, "hardware", None),
        data_dir=getattr(args, "data_dir", None),
        token=getattr(args, "token", None),
    )
    settings, generated = with_token(settings)
    lock_data_dir(settings.data_dir).close()  # fail now, with a clear message, rather than in the lifespan
    sock = _listen(settings.host, settings.port)
    port = sock.getsockname()[1]
    app = create_app(settings)
    token = settings.token_value
    print(f"sonarslam {__version__}: {settings.hardware} runs, data in {settings.data_dir.resolve()}")
    for url in urls(settings, port):
        print(f"  {url}?token={token}" if token and generated else f"  {url}")
    if token and not generated:
        print("  control endpoints need the configured token (Authorization: Bearer ...)")
    if not settings.loopback_only:
        print("  reachable from other machines: keep the token secret", file=sys.stderr)
    sys.stdout.flush()
    config = uvicorn.Config(
        app,
        log_level=settings.log_level,
        # Offered, never imposed: a viewer that does not ask for it gets plain frames. uvicorn's websockets-sansio
        # protocol (its choice when websockets is installed) keeps a compressor per viewer: 4 kB window, memLevel 5,
        # context kept between messages.
        ws_per_message_deflate=settings.ws_compression,
        ws_max_size=64 * 1024,
        timeout_graceful_shutdown=5,
        lifespan="on",
    )
    server = Server(config, app)
    for name in ("uvicorn.access", "uvicorn.error"):
        logging.getLogger(name).addFilter(RedactTokens())
    try:
        server.run(sockets=[sock])
    finally:
        sock.close()
    return 0 if server.started else 1
