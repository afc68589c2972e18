"""The sensor log: a simple text format for recorded runs, written live and read back for replay.

One record per line, fields separated by spaces, times in seconds, lengths in metres::

    # sonarslam-log 1 {"sonars": [...], "sonar": {...}, "frame": {...}}   (header: JSON metadata)
    O <t> <left_counts> <right_counts>     where dead reckoning starts (once, first)
    I <t> <gyro_z_rad_s>                   an IMU sample
    E <t> <left_counts> <right_counts> <driving 0|1>
                                           encoder counts; a dead-reckoning update with the IMU
                                           samples logged since the previous E
    S <t> <r_0> ... <r_n-1>                a sonar sweep (mounting order; max range = no echo)
    P <t> <x> <y> <theta_rad>              an odometry pose, for logs without encoders
    B <t> <direction_rad>                  the body touched something while driving this way

Lines starting with ``#`` after the header are comments. The header carries the sonar layout and
the map frame so that ``sonarslam replay`` rebuilds the same map.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from robot.errors import LogFormatError
from robot.hardware import EncoderCounts, ImuSample, SonarSweep

MAGIC = "# sonarslam-log 1"


class SensorLogWriter:
    """Appends records to a log file, flushing each batch so a crash loses at most one step."""

    def __init__(self, path: Path | str, meta: dict[str, Any]) -> None:
        self.path = Path(path)
        self._fh: IO[str] | None = open(self.path, "w", encoding="utf-8")  # noqa: SIM115 - closed in close()
        self._fh.write(f"{MAGIC} {json.dumps(meta, separators=(',', ':'))}\n")
        self._fh.flush()

    def _write(self, line: str) -> None:
        if self._fh is not None:
            self._fh.write(line)

    def dead_reckoning(self, counts: EncoderCounts, imu: Sequence[ImuSample], driving: bool) -> None:
        # Full precision (repr) so that a replay reproduces the run bit for bit.
        for s in imu:
            self._write(f"I {s.t_s!r} {s.gyro_z_rad_s!r}\n")
        self._write(f"E {counts.t_s!r} {counts.left} {counts.right} {int(driving)}\n")

    def origin(self, counts: EncoderCounts) -> None:
        """The encoder counts and clock time that dead reckoning starts from."""
        self._write(f"O {counts.t_s!r} {counts.left} {counts.right}\n")

    def sweep(self, sweep: SonarSweep) -> None:
        self._write(f"S {float(sweep.t_s)!r} " + " ".join(repr(float(r)) for r in sweep.ranges_m) + "\n")
        self.flush()

    def contact(self, t_s: float, direction_rad: float) -> None:
        self._write(f"B {float(t_s)!r} {float(direction_rad)!r}\n")

    def flush(self) -> None:
        if self._fh is not None:
            self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


@dataclass(frozen=True)
class LogRecord:
    kind: str  # "O", "I", "E", "S", "P", "B"
    t_s: float
    values: tuple[float, ...]

    @property
    def ranges(self) -> NDArray[np.float64]:
        return np.asarray(self.values, dtype=float)


def read_sensor_log(path: Path | str) -> tuple[dict[str, Any], Iterator[LogRecord]]:
    """The header metadata and an iterator over the records; errors name the file and line."""
    p = Path(path)
    try:
        fh = open(p, encoding="utf-8")  # noqa: SIM115 - closed by the generator
    except OSError as exc:
        raise LogFormatError(f"{p}: cannot read: {exc.strerror}") from None
    first = fh.readline()
    if not first.startswith(MAGIC):
        fh.close()
        raise LogFormatError(f"{p}: line 1: not a sonarslam sensor log (expected '{MAGIC} {{...}}')")
    try:
        meta = json.loads(first[len(MAGIC) :].strip() or "{}")
    except json.JSONDecodeError as exc:
        fh.close()
        raise LogFormatError(f"{p}: line 1: bad header JSON: {exc.msg}") from None
    if not isinstance(meta, dict):
        fh.close()
        raise LogFormatError(f"{p}: line 1: header must be a JSON object")

    arity = {"I": 1, "E": 3, "P": 3, "B": 1, "O": 2}

    def records() -> Iterator[LogRecord]:
        with fh:
            for lineno, line in enumerate(fh, start=2):
                line = line.strip()
                if not line or line.startswith("#"):
                    continue
                parts = line.split()
                kind = parts[0]
                try:
                    nums = tuple(float(x) for x in parts[1:])
                except ValueError:
                    raise LogFormatError(f"{p}: line {lineno}: non-numeric field in {kind!r} record") from None
                if kind not in ("I", "E", "S", "P", "B", "O"):
                    raise LogFormatError(f"{p}: line {lineno}: unknown record type {kind!r}")
                if not nums or (kind in arity and len(nums) - 1 != arity[kind]) or (kind == "S" and len(nums) < 2):
                    raise LogFormatError(f"{p}: line {lineno}: wrong number of fields for a {kind!r} record")
                if not all(math.isfinite(v) for v in nums):
                    raise LogFormatError(f"{p}: line {lineno}: non-finite value")
                yield LogRecord(kind, nums[0], nums[1:])

    return meta, records()
