"""Liveness: ``GET /api/health``."""

from __future__ import annotations

from fastapi import APIRouter

from server.models import Health

router = APIRouter(tags=["health"])


@router.get("/api/health")
async def health() -> Health:
    return Health()
