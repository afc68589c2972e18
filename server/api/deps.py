"""Shared route dependencies: the run manager, the settings, run ids and bearer-token checks."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends, Path, Query, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.requests import HTTPConnection

from server.errors import ApiError
from server.models import RUN_ID_PATTERN
from server.runs import RunManager
from server.settings import ServerSettings

bearer = HTTPBearer(auto_error=False, description="the service's token, when it requires one")


def get_settings(conn: HTTPConnection) -> ServerSettings:
    settings: ServerSettings = conn.app.state.settings
    return settings


def get_manager(conn: HTTPConnection) -> RunManager:
    manager: RunManager = conn.app.state.manager
    return manager


# Dependencies are coroutines: FastAPI would run plain functions on a worker thread, a costly hop.
async def settings_dep(conn: HTTPConnection) -> ServerSettings:
    return get_settings(conn)


async def manager_dep(conn: HTTPConnection) -> RunManager:
    return get_manager(conn)


SettingsDep = Annotated[ServerSettings, Depends(settings_dep)]
ManagerDep = Annotated[RunManager, Depends(manager_dep)]
RunId = Annotated[str, Path(pattern=RUN_ID_PATTERN, max_length=24, description="run id, as r-YYYYMMDD-NNNN")]


def token_ok(settings: ServerSettings, presented: str | None) -> bool:
    expected = settings.token_value
    if expected is None:
        return not settings.token_required
    return presented is not None and secrets.compare_digest(presented.encode(), expected.encode())


async def require_control(
    request: Request, creds: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)]
) -> None:
    """Start, stop, delete, upload and configure need ``Authorization: Bearer TOKEN`` when a token is set.

    Only the header counts here (never a query string or cookie), so another site cannot make a
    visitor's browser send a control request."""
    settings = get_settings(request)
    if settings.token_required and not token_ok(settings, creds.credentials if creds else None):
        raise ApiError(401, "this endpoint needs 'Authorization: Bearer TOKEN' with the service's token")


async def require_view(
    request: Request,
    creds: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
    token: Annotated[str | None, Query(max_length=256, description="the token, where a header cannot be set")] = None,
) -> None:
    """Viewing is open unless configured token-only; then the header or a ``token`` query parameter."""
    settings = get_settings(request)
    if settings.view_access == "token" and not (
        token_ok(settings, creds.credentials if creds else None) or token_ok(settings, token)
    ):
        raise ApiError(401, "viewing needs the service's token ('Authorization: Bearer TOKEN' or ?token=)")


Control = Depends(require_control)
View = Depends(require_view)
