"""SRF02/SRF08 sonars on I2C: start a ranging in centimetres, wait, read the 16-bit result."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import TypeVar

from robot.errors import HardwareError
from robot.pi.i2c import I2cBus, retry_busy
from robot.pi.sonar import Ping

REG_COMMAND = 0x00  # write: command; read: software revision
REG_RANGE_HIGH = 0x02  # registers 2-3: last range, high byte first
CMD_RANGE_CM = 0x51
T = TypeVar("T")
RETRY_WAIT_S = 0.005


class Srf02Bank:
    """SRF02/SRF08 sonars at 7-bit addresses 0x70-0x7F, pinged one at a time.

    While ranging (up to 65 ms) the device does not acknowledge its address, which reads as
    OSError 121 on the Pi; every transaction is retried for a while before giving up.
    """

    def __init__(
        self,
        bus: I2cBus,
        addresses: Sequence[int],
        *,
        bus_number: int,
        max_range_m: float,
        ranging_time_s: float = 0.07,
        retries: int = 10,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self._bus = bus
        self.addresses = tuple(addresses)
        self.bus_number = bus_number
        self.max_range_m = max_range_m
        self.ranging_time_s = ranging_time_s
        self.retries = retries
        self._sleep = sleep
        self.revisions: list[int] = [self._revision(a) for a in self.addresses]

    def __len__(self) -> int:
        return len(self.addresses)

    def _revision(self, address: int) -> int:
        try:
            return self._retry(lambda: self._bus.read_byte_data(address, REG_COMMAND))
        except OSError as exc:
            raise HardwareError(
                f"no SRF02 answers on I2C bus {self.bus_number} at {address:#04x} ({exc.strerror or exc}); "
                f"check wiring and `i2cdetect -y {self.bus_number}`"
            ) from None

    def ping(self, index: int) -> Ping:
        address = self.addresses[index]
        try:
            self._retry(lambda: self._bus.write_byte_data(address, REG_COMMAND, CMD_RANGE_CM))
            self._sleep(self.ranging_time_s)
            high, low = self._retry(lambda: self._bus.read_i2c_block_data(address, REG_RANGE_HIGH, 2))
        except OSError:
            # One lost transaction should not end a run: report it like a missing echo.
            return Ping(self.max_range_m, "no-response")
        range_cm = (high << 8) | low
        range_m = range_cm / 100.0
        if range_cm == 0 or range_m >= self.max_range_m:  # 0 means nothing was heard
            return Ping(self.max_range_m, "no-echo")
        return Ping(range_m, "echo")

    def _retry(self, action: Callable[[], T]) -> T:
        return retry_busy(action, self.retries, RETRY_WAIT_S, self._sleep)

    def close(self) -> None:
        """The bus is shared and closed by its owner."""
