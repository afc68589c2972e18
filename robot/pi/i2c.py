"""I2C access for the Pi drivers: the bus interface they need, a thread-safe wrapper and the smbus2 opener."""

from __future__ import annotations

import errno
import threading
from collections.abc import Callable, Sequence
from typing import Protocol, TypeVar

from robot.errors import HardwareError

# A device that is busy (an SRF02 while ranging) or absent does not acknowledge: on the Pi's
# i2c-bcm2835 driver that is EREMOTEIO (121); some adapters report EIO or a timeout instead.
BUSY_ERRNOS = frozenset({errno.EREMOTEIO, errno.EIO, errno.ETIMEDOUT})

T = TypeVar("T")


class I2cBus(Protocol):
    """The subset of ``smbus2.SMBus`` the drivers use; tests pass a fake with register maps."""

    def read_byte_data(self, i2c_addr: int, register: int) -> int: ...

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None: ...

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> Sequence[int]: ...

    def close(self) -> None: ...


BusFactory = Callable[[int], I2cBus]


class LockedBus:
    """Serialises transactions so the IMU thread and the sonar loop can share one bus.

    smbus2 selects the slave address and then issues the transfer in two system calls; two threads
    interleaving them would talk to the wrong device.
    """

    def __init__(self, bus: I2cBus, number: int) -> None:
        self._bus = bus
        self.number = number
        self._lock = threading.Lock()
        self._closed = False

    def read_byte_data(self, i2c_addr: int, register: int) -> int:
        with self._lock:
            return self._bus.read_byte_data(i2c_addr, register)

    def write_byte_data(self, i2c_addr: int, register: int, value: int) -> None:
        with self._lock:
            self._bus.write_byte_data(i2c_addr, register, value)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> Sequence[int]:
        with self._lock:
            return self._bus.read_i2c_block_data(i2c_addr, register, length)

    def close(self) -> None:
        with self._lock:
            if not self._closed:
                self._closed = True
                self._bus.close()


def open_smbus(number: int) -> I2cBus:
    """Open ``/dev/i2c-<number>`` with smbus2 (imported here, so only a Pi run needs it)."""
    from smbus2 import SMBus

    try:
        return SMBus(number)
    except FileNotFoundError:
        raise HardwareError(f"I2C bus {number} not found (/dev/i2c-{number}): enable I2C with raspi-config") from None
    except PermissionError:
        raise HardwareError(f"I2C bus {number}: no access to /dev/i2c-{number}: add the user to group i2c") from None
    except OSError as exc:
        raise HardwareError(f"I2C bus {number}: cannot open /dev/i2c-{number}: {exc.strerror}") from None


def retry_busy(action: Callable[[], T], attempts: int, wait_s: float, sleep: Callable[[float], None]) -> T:
    """Run ``action``, retrying up to ``attempts`` more times while the device does not acknowledge."""
    for attempt in range(attempts + 1):
        try:
            return action()
        except OSError as exc:
            if exc.errno not in BUSY_ERRNOS or attempt == attempts:
                raise
            sleep(wait_s)
    raise AssertionError("unreachable")  # pragma: no cover
