"""The default run configuration: read it, or update it (validated, then persisted)."""

from __future__ import annotations

from fastapi import APIRouter

from server.api.deps import Control, ManagerDep, View
from server.models import ConfigUpdate, ErrorBody, RunDefaults

router = APIRouter(tags=["config"])


@router.get("/api/config", dependencies=[View])
async def get_config(manager: ManagerDep) -> RunDefaults:
    return manager.defaults()


@router.put("/api/config", dependencies=[Control], responses={422: {"model": ErrorBody}})
async def put_config(manager: ManagerDep, update: ConfigUpdate) -> RunDefaults:
    """Fields given replace the current defaults, the others stay; new runs use the result."""
    return await manager.update_defaults(update)
