"""Worlds: list the built-in and uploaded ones, upload a new one (validated)."""

from __future__ import annotations

import asyncio
from typing import Annotated

from fastapi import APIRouter, File, UploadFile

from server.api.deps import Control, ManagerDep, View
from server.errors import ApiError
from server.models import ErrorBody, WorldInfo

router = APIRouter(tags=["worlds"])


@router.get("/api/worlds", dependencies=[View])
async def list_worlds(manager: ManagerDep) -> list[WorldInfo]:
    return await asyncio.to_thread(manager.catalog.infos)


@router.post(
    "/api/worlds",
    status_code=201,
    dependencies=[Control],
    responses={409: {"model": ErrorBody}, 413: {"model": ErrorBody}, 422: {"model": ErrorBody}},
)
async def upload_world(
    manager: ManagerDep, file: Annotated[UploadFile, File(description="a world TOML file (SPEC §1)")]
) -> WorldInfo:
    """Validate a world file and keep it under the ``name`` it declares (a built-in name is refused)."""
    limit = manager.catalog.max_bytes
    data = await file.read(limit + 1)
    if len(data) > limit:
        raise ApiError(413, f"world file is larger than {limit} bytes", ["body", "file"])
    return await asyncio.to_thread(manager.catalog.upload, file.filename, data)
