"""API errors: every problem a client can cause becomes a 4xx naming the field at fault."""

from __future__ import annotations

from collections.abc import Sequence

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from robot.errors import HardwareError, SonarSlamError


class ApiError(Exception):
    """A client error with its HTTP status and, when one field is at fault, that field's location."""

    def __init__(self, status: int, msg: str, loc: Sequence[str | int] | None = None, kind: str = "value_error"):
        super().__init__(msg)
        self.status = status
        self.msg = msg
        self.loc = list(loc) if loc is not None else None
        self.kind = kind

    def body(self) -> dict[str, object]:
        if self.loc is None:
            return {"detail": self.msg}
        return {"detail": [{"loc": self.loc, "msg": self.msg, "type": self.kind}]}


def field_error(loc: Sequence[str | int], msg: str, status: int = 422) -> ApiError:
    return ApiError(status, msg, loc)


def not_found(what: str) -> ApiError:
    return ApiError(404, f"{what} not found")


def conflict(msg: str) -> ApiError:
    return ApiError(409, msg)


def install_error_handlers(app: FastAPI) -> None:
    async def api_error(request: Request, exc: Exception) -> JSONResponse:
        assert isinstance(exc, ApiError)
        headers = {"WWW-Authenticate": "Bearer"} if exc.status == 401 else None
        return JSONResponse(exc.body(), status_code=exc.status, headers=headers)

    async def project_error(request: Request, exc: Exception) -> JSONResponse:
        # Bad input raises ValueErrors with a one-line message; a robot that cannot be reached is not
        # the client's fault but not a crash either.
        status = 503 if isinstance(exc, HardwareError) else 422
        return JSONResponse({"detail": str(exc)}, status_code=status)

    app.add_exception_handler(ApiError, api_error)
    app.add_exception_handler(SonarSlamError, project_error)
