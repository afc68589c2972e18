"""The live map WebSocket ``/ws/runs/{id}`` (docs/protocol.md): hello, snapshot, steps, status."""

from __future__ import annotations

import asyncio
import contextlib
import json
import re

from fastapi import APIRouter, WebSocket
from fastapi.responses import JSONResponse
from starlette.websockets import WebSocketDisconnect

from server.api.deps import get_manager, get_settings, token_ok
from server.broadcast import Outgoing, Subscriber, encode
from server.live import LiveRun
from server.models import RUN_ID_PATTERN
from server.wire import PROTOCOL_VERSION

router = APIRouter()
_RUN_ID = re.compile(RUN_ID_PATTERN)


async def _deny(websocket: WebSocket, status: int, detail: str) -> None:
    """Refuse the handshake with an HTTP status (or close code 1008 where the server cannot)."""
    if "websocket.http.response" in websocket.scope.get("extensions", {}):
        await websocket.send_denial_response(JSONResponse({"detail": detail}, status_code=status))
    else:
        await websocket.close(code=1008, reason=detail[:120])


def _bearer(websocket: WebSocket) -> str | None:
    scheme, _, value = websocket.headers.get("authorization", "").partition(" ")
    return value.strip() if scheme.lower() == "bearer" else None


async def _read(websocket: WebSocket, live: LiveRun, sub: Subscriber) -> None:
    """The viewer's requests: ``resync`` and ``ping``; anything else is ignored."""
    try:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                break
            try:
                request = json.loads(message.get("text") or "")
            except ValueError:
                continue
            kind = request.get("type") if isinstance(request, dict) else None
            if kind == "resync":
                live.resync(sub)
            elif kind == "ping":
                sub.put(Outgoing.of({"type": "pong"}))
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        sub.close(drop=True)


@router.websocket("/ws/runs/{run_id}")
async def live_run(websocket: WebSocket, run_id: str) -> None:
    settings = get_settings(websocket)
    manager = get_manager(websocket)
    if settings.view_access == "token" and not (
        token_ok(settings, _bearer(websocket)) or token_ok(settings, websocket.query_params.get("token"))
    ):
        await _deny(websocket, 401, "viewing needs the service's token (?token=)")
        return
    record = manager.store.get(run_id) if _RUN_ID.fullmatch(run_id) else None
    if record is None:
        await _deny(websocket, 404, f"run {run_id[:40]} not found")
        return
    live = manager.live_view(run_id)
    if live is None:
        live = await asyncio.to_thread(manager.ended_live, record)
    await websocket.accept()
    sub = live.subscribe()
    reader = asyncio.create_task(_read(websocket, live, sub))
    # Served from a task of its own: each of the viewer's wake-ups (up to ws_max_rate_hz a second) then
    # resumes one short coroutine rather than the two dozen frames of middleware and routing above this.
    sender = asyncio.create_task(_send(websocket, live, sub, run_id, settings.ws_max_rate_hz))
    try:
        await sender
    except (WebSocketDisconnect, RuntimeError):
        pass  # the viewer went away (RuntimeError: the socket was already closed)
    finally:
        sender.cancel()
        live.unsubscribe(sub)
        reader.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await reader


async def _send(websocket: WebSocket, live: LiveRun, sub: Subscriber, run_id: str, max_rate_hz: float) -> None:
    """hello, then the viewer's queue until it closes; steps at most ``max_rate_hz`` a second."""
    min_interval_s = 1.0 / max_rate_hz
    timing = websocket.query_params.get("timing") == "1"  # steps also say when they ended on the server
    hello = {"type": "hello", "protocol": PROTOCOL_VERSION, "session": websocket.app.state.session_id}
    await websocket.send_text(encode({**hello, "run_id": run_id}))
    while (item := await sub.get()) is not None:
        if item.kind == "step":
            item = sub.fold(item)  # the steps that came while this viewer was served go as one
        await websocket.send_text(item.wire(timing))
        if item.terminal:
            await websocket.close(code=1000)
            break
        if item.kind == "step":
            # Pace a viewer of a fast run: nothing more until the run's next tick, which all its
            # viewers share, so that one wake-up of the loop serves them all (the steps that come
            # meanwhile are merged). After a quiet spell a step goes out at once.
            await live.ticker.wait(min_interval_s)
