"""The world catalog: the built-in worlds plus validated uploads kept in the data directory."""

from __future__ import annotations

import math
import re
import threading
from pathlib import Path, PurePath

from robot.errors import WorldError
from robot.mapio import atomic_write_bytes
from robot.world import World, builtin_worlds, load_world_text
from server.errors import ApiError, conflict, field_error
from server.models import WORLD_NAME_PATTERN, WorldInfo

_NAME = re.compile(WORLD_NAME_PATTERN)


def world_info(world: World, source: str) -> WorldInfo:
    min_x, min_y, max_x, max_y = world.bounds
    return WorldInfo(
        name=world.name,
        source="builtin" if source == "builtin" else "uploaded",
        description=world.description,
        width_m=round(max_x - min_x, 4),
        height_m=round(max_y - min_y, 4),
        obstacles=len(world.obstacles),
        start={
            "x": world.start.x,
            "y": world.start.y,
            "theta_deg": round(math.degrees(world.start.theta), 6),
        },
    )


class WorldCatalog:
    """Finds worlds by name only: a name never becomes a path outside the catalog's folders."""

    def __init__(self, upload_dir: Path, max_bytes: int) -> None:
        self.upload_dir = upload_dir
        self.max_bytes = max_bytes
        self._lock = threading.Lock()
        self._cache: dict[tuple[str, float], World] = {}
        upload_dir.mkdir(parents=True, exist_ok=True)

    def _files(self) -> dict[str, tuple[Path, str]]:
        files: dict[str, tuple[Path, str]] = {}
        for p in sorted(self.upload_dir.glob("*.toml")):
            if _NAME.fullmatch(p.stem):
                files[p.stem] = (p, "uploaded")
        files.update({name: (p, "builtin") for name, p in builtin_worlds().items()})
        return files

    def names(self) -> list[str]:
        return list(self._files())

    def source(self, name: str) -> str | None:
        entry = self._files().get(name)
        return entry[1] if entry else None

    def text(self, name: str) -> str:
        entry = self._files().get(name) if _NAME.fullmatch(name) else None
        if entry is None:
            raise field_error(["body", "world"], f"unknown world {name!r} (known: {', '.join(self.names())})")
        return entry[0].read_text(encoding="utf-8")

    def load(self, name: str) -> World:
        """The world called ``name``; a 422 naming the ``world`` field if there is none."""
        entry = self._files().get(name) if _NAME.fullmatch(name) else None
        if entry is None:
            raise field_error(["body", "world"], f"unknown world {name!r} (known: {', '.join(self.names())})")
        path, _source = entry
        key = (str(path), path.stat().st_mtime)
        with self._lock:
            cached = self._cache.get(key)
        if cached is not None:
            return cached
        world = load_world_text(path.read_text(encoding="utf-8"), path.name)
        with self._lock:
            self._cache[key] = world
        return world

    def infos(self) -> list[WorldInfo]:
        return [world_info(self.load(name), source) for name, (_p, source) in self._files().items()]

    def upload(self, filename: str | None, data: bytes) -> WorldInfo:
        """Validate an uploaded world TOML and keep it under its ``name``. Raises ApiError (4xx)."""
        loc = ["body", "file"]
        if len(data) > self.max_bytes:
            raise ApiError(413, f"world file is larger than {self.max_bytes} bytes", loc)
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise field_error(loc, "world file is not UTF-8 text") from None
        source = PurePath(filename or "upload.toml").name or "upload.toml"
        try:
            world = load_world_text(text, source)
        except WorldError as exc:
            raise field_error(loc, str(exc)) from None
        if not _NAME.fullmatch(world.name):
            raise field_error(loc, f"{source}: name {world.name!r} must match {WORLD_NAME_PATTERN}")
        if world.name in builtin_worlds():
            raise conflict(f"{world.name!r} is a built-in world; give the upload another name")
        atomic_write_bytes(self.upload_dir / f"{world.name}.toml", text.encode("utf-8"))
        return world_info(world, "uploaded")
