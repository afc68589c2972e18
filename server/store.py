"""Run records in SQLite (WAL): configuration, status, timestamps, progress and metrics."""

from __future__ import annotations

import json
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ACTIVE = ("queued", "running")
ENDED = ("finished", "stopped", "interrupted", "error")

_SCHEMA = """
CREATE TABLE IF NOT EXISTS runs (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    id TEXT NOT NULL UNIQUE,
    status TEXT NOT NULL,
    hardware TEXT NOT NULL,
    world TEXT,
    config TEXT NOT NULL,           -- the resolved run options, JSON
    grid TEXT NOT NULL,             -- rows, cols, resolution, origin, JSON
    created_at REAL NOT NULL,       -- Unix time [s]
    started_at REAL,
    ended_at REAL,
    updated_at REAL NOT NULL,
    steps INTEGER NOT NULL DEFAULT 0,
    sim_time_s REAL NOT NULL DEFAULT 0,
    explored REAL,
    frontier INTEGER,
    wall_time_s REAL,
    terminated_by TEXT,
    metrics TEXT,                   -- JSON
    error TEXT
);
CREATE TABLE IF NOT EXISTS settings (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""


@dataclass
class RunRecord:
    id: str
    status: str
    hardware: str
    world: str | None
    config: dict[str, Any]
    grid: dict[str, Any]
    created_at: float
    started_at: float | None = None
    ended_at: float | None = None
    updated_at: float = 0.0
    steps: int = 0
    sim_time_s: float = 0.0
    explored: float | None = None
    frontier: int | None = None
    wall_time_s: float | None = None
    terminated_by: str | None = None
    metrics: dict[str, Any] | None = None
    error: str | None = None

    @classmethod
    def from_row(cls, row: sqlite3.Row) -> RunRecord:
        return cls(
            id=row["id"],
            status=row["status"],
            hardware=row["hardware"],
            world=row["world"],
            config=json.loads(row["config"]),
            grid=json.loads(row["grid"]),
            created_at=row["created_at"],
            started_at=row["started_at"],
            ended_at=row["ended_at"],
            updated_at=row["updated_at"],
            steps=row["steps"],
            sim_time_s=row["sim_time_s"],
            explored=row["explored"],
            frontier=row["frontier"],
            wall_time_s=row["wall_time_s"],
            terminated_by=row["terminated_by"],
            metrics=json.loads(row["metrics"]) if row["metrics"] else None,
            error=row["error"],
        )


class RunStore:
    """One SQLite connection shared by the event loop and the run threads, serialised by a lock (a run in a
    child process opens one of its own: WAL lets processes share the file).

    Every statement is short; commits are durable (``synchronous=FULL``) so that a run recorded as
    finished stays finished after a crash.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._lock = threading.Lock()
        self._db = sqlite3.connect(path, check_same_thread=False, isolation_level=None, timeout=10.0)
        self._db.row_factory = sqlite3.Row
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=FULL")
        self._db.executescript(_SCHEMA)

    def close(self) -> None:
        with self._lock:
            self._db.close()

    @contextmanager
    def _tx(self) -> Iterator[sqlite3.Connection]:
        with self._lock:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                yield self._db
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
            self._db.execute("COMMIT")

    # -- runs ----------------------------------------------------------------------------------
    def create_run(self, hardware: str, world: str | None, config: dict[str, Any], grid: dict[str, Any]) -> RunRecord:
        """Insert a queued run and give it an id ``r-YYYYMMDD-NNNN`` (never reused)."""
        now = time.time()
        day = time.strftime("%Y%m%d", time.gmtime(now))
        with self._tx() as db:
            cur = db.execute(
                "INSERT INTO runs (id, status, hardware, world, config, grid, created_at, updated_at) "
                "VALUES ('pending', 'queued', ?, ?, ?, ?, ?, ?)",
                (hardware, world, json.dumps(config), json.dumps(grid), now, now),
            )
            run_id = f"r-{day}-{cur.lastrowid:04d}"
            db.execute("UPDATE runs SET id = ? WHERE seq = ?", (run_id, cur.lastrowid))
        record = self.get(run_id)
        assert record is not None
        return record

    def get(self, run_id: str) -> RunRecord | None:
        with self._lock:
            row = self._db.execute("SELECT * FROM runs WHERE id = ?", (run_id,)).fetchone()
        return RunRecord.from_row(row) if row is not None else None

    def list_runs(self, limit: int = 1000) -> list[RunRecord]:
        with self._lock:
            rows = self._db.execute("SELECT * FROM runs ORDER BY seq DESC LIMIT ?", (limit,)).fetchall()
        return [RunRecord.from_row(r) for r in rows]

    def count(self, statuses: tuple[str, ...]) -> int:
        marks = ",".join("?" * len(statuses))
        with self._lock:
            row = self._db.execute(f"SELECT COUNT(*) FROM runs WHERE status IN ({marks})", statuses).fetchone()
        return int(row[0])

    def update(self, run_id: str, **values: Any) -> None:
        """Set columns of one run; dicts are stored as JSON."""
        allowed = {
            "status", "started_at", "ended_at", "steps", "sim_time_s", "explored", "frontier",
            "wall_time_s", "terminated_by", "metrics", "error", "config",
        }  # fmt: skip
        unknown = set(values) - allowed
        if unknown:
            raise KeyError(f"unknown run columns: {sorted(unknown)}")
        values["updated_at"] = time.time()
        for key in ("metrics", "config"):
            if isinstance(values.get(key), dict):
                values[key] = json.dumps(values[key])
        columns = ", ".join(f"{k} = ?" for k in values)
        with self._tx() as db:
            db.execute(f"UPDATE runs SET {columns} WHERE id = ?", (*values.values(), run_id))

    def delete(self, run_id: str) -> bool:
        with self._tx() as db:
            return db.execute("DELETE FROM runs WHERE id = ?", (run_id,)).rowcount > 0

    def mark_interrupted(self) -> list[str]:
        """After a crash: every run that was queued or running is now ``interrupted``. Returns their ids."""
        now = time.time()
        with self._tx() as db:
            ids = [r[0] for r in db.execute("SELECT id FROM runs WHERE status IN ('queued', 'running')").fetchall()]
            db.execute(
                "UPDATE runs SET status = 'interrupted', terminated_by = COALESCE(terminated_by, 'interrupted'), "
                "ended_at = COALESCE(ended_at, updated_at), updated_at = ? WHERE status IN ('queued', 'running')",
                (now,),
            )
        return ids

    # -- settings ------------------------------------------------------------------------------
    def get_setting(self, key: str) -> Any | None:
        with self._lock:
            row = self._db.execute("SELECT value FROM settings WHERE key = ?", (key,)).fetchone()
        return json.loads(row[0]) if row is not None else None

    def put_setting(self, key: str, value: Any) -> None:
        with self._tx() as db:
            db.execute(
                "INSERT INTO settings (key, value) VALUES (?, ?) ON CONFLICT(key) DO UPDATE SET value = excluded.value",
                (key, json.dumps(value)),
            )
