"""Runs: start, list, inspect, change speed, stop, delete, and download their files."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import APIRouter, Response

from server.api.deps import Control, ManagerDep, RunId, View
from server.downloads import MEDIA_TYPES, bundle, live_files, read_file
from server.errors import ApiError
from server.models import ErrorBody, RunCreate, RunPatch, RunView
from server.runs import RunManager
from server.store import ACTIVE

router = APIRouter(tags=["runs"])
ERRORS: dict[int | str, dict[str, Any]] = {code: {"model": ErrorBody} for code in (404, 409, 422)}


@router.post("/api/runs", status_code=201, dependencies=[Control], responses={**ERRORS, 429: {"model": ErrorBody}})
async def create_run(manager: ManagerDep, body: RunCreate, response: Response) -> RunView:
    """Start a run; fields left out come from the default run configuration (``GET /api/config``).

    When every slot is busy a simulated run waits as ``queued``. The robot runs one at a time: while
    it is busy, another start is refused with 409."""
    record = await manager.create(body)
    response.headers["Location"] = f"/api/runs/{record.id}"
    return manager.view(record)


@router.get("/api/runs", dependencies=[View])
async def list_runs(manager: ManagerDep) -> list[RunView]:
    """Every run, newest first."""
    return manager.list_views()


@router.get("/api/runs/{run_id}", dependencies=[View], responses=ERRORS)
async def get_run(manager: ManagerDep, run_id: RunId) -> RunView:
    return manager.view(manager.record(run_id))


@router.patch("/api/runs/{run_id}", dependencies=[Control], responses=ERRORS)
async def patch_run(manager: ManagerDep, run_id: RunId, body: RunPatch) -> RunView:
    """Change what can change while a run goes on: its speed (simulated runs)."""
    return manager.view(manager.set_speed(run_id, body.speed))


@router.post("/api/runs/{run_id}/stop", dependencies=[Control], responses=ERRORS)
async def stop_run(manager: ManagerDep, run_id: RunId) -> RunView:
    """End the run after its current step; its partial map is kept. Answers once it has ended."""
    return manager.view(await manager.stop(run_id))


@router.delete("/api/runs/{run_id}", status_code=204, dependencies=[Control], responses=ERRORS)
async def delete_run(manager: ManagerDep, run_id: RunId) -> Response:
    """Stop the run if it is going on, then remove it and its files."""
    await manager.delete(run_id)
    return Response(status_code=204)


async def download(manager: RunManager, run_id: str, name: str) -> Response:
    record = manager.record(run_id)
    run_dir = manager.run_dir(run_id)
    live = manager.live_view(run_id)
    session = manager.sessions.get(run_id)
    current: dict[str, bytes] | None = None
    if live is not None and not live.ended and record.status in ACTIVE:
        trajectory = list(session.trajectory) if session is not None else []
        names = tuple(MEDIA_TYPES) if name == "bundle.zip" else (name,)
        current = await asyncio.to_thread(live_files, live.states(), live.grid, trajectory, names)
    if name == "bundle.zip":
        run_json = manager.view(record).model_dump(mode="json")
        data: bytes | None = await asyncio.to_thread(bundle, run_id, run_dir, current, run_json)
        filename = f"{run_id}.zip"
    else:
        data = await asyncio.to_thread(read_file, run_dir, name, current)
        filename = name
    if data is None:
        raise ApiError(404, f"run {run_id} has no {name} yet ({record.status})")
    headers = {"Content-Disposition": f'attachment; filename="{filename}"', "Cache-Control": "no-store"}
    return Response(content=data, media_type=MEDIA_TYPES[name], headers=headers)


def _download_route(name: str) -> Callable[[RunManager, str], Awaitable[Response]]:
    async def endpoint(manager: ManagerDep, run_id: RunId) -> Response:
        return await download(manager, run_id, name)

    endpoint.__name__ = "download_" + name.replace(".", "_")
    return endpoint


for _name in MEDIA_TYPES:
    router.add_api_route(
        f"/api/runs/{{run_id}}/{_name}",
        _download_route(_name),
        methods=["GET"],
        dependencies=[View],
        responses={200: {"content": {MEDIA_TYPES[_name].split(";")[0]: {}}}, **ERRORS},
        response_class=Response,
        summary=f"Download {_name}" + (" (every file, zipped)" if _name == "bundle.zip" else ""),
        description="During a run, the current snapshot; afterwards, the saved file.",
    )
