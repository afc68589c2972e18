"""Raspberry Pi backend: gpiozero/smbus2 drivers behind the Hardware seam (imported only when chosen).

Importing this package, ``robot.pi.config``, ``robot.pi.safety`` or ``robot.pi.check`` does not
import gpiozero or smbus2; the driver modules do, and ``PiHardware`` is loaded on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from robot.pi.hardware import PiHardware

__all__ = ["PiHardware"]


def __getattr__(name: str) -> Any:
    if name == "PiHardware":
        from robot.pi.hardware import PiHardware

        return PiHardware
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
