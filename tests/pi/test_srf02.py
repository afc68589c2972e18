"""SRF02/SRF08 over I2C against a fake register map: ranging, busy retries, no echo, missing devices."""

from __future__ import annotations

import pytest
from pi_configs import robot_pi_toml, srf02_ring

from robot.errors import HardwareError
from robot.pi.srf02 import Srf02Bank


def make_bank(bus, addresses, sleeps=None, **kwargs) -> Srf02Bank:
    record = sleeps.append if sleeps is not None else (lambda s: None)
    return Srf02Bank(bus, addresses, bus_number=1, max_range_m=4.0, sleep=record, **kwargs)


def test_ranges_in_cm_high_byte_first_after_waiting(i2c_bus, srf02_class):
    sonar = i2c_bus.attach(0x70, srf02_class(range_cm=0x0123, busy_after_command=3))
    sleeps: list[float] = []
    bank = make_bank(i2c_bus, [0x70], sleeps)
    ping = bank.ping(0)
    assert (ping.status, ping.range_m) == ("echo", pytest.approx(2.91))
    assert sonar.writes == [(0, 0x51)]  # range in centimetres
    assert max(sleeps) >= 0.07  # the ranging wait
    assert sonar.busy == 0  # the reads were retried through the deaf period
    assert sonar.block_reads == [(2, 2)]


def test_zero_means_no_echo_and_far_reads_max_range(i2c_bus, srf02_class):
    near = i2c_bus.attach(0x70, srf02_class(range_cm=0))
    i2c_bus.attach(0x71, srf02_class(range_cm=600))
    bank = make_bank(i2c_bus, [0x70, 0x71])
    assert bank.ping(0).status == "no-echo" and bank.ping(0).range_m == 4.0
    assert bank.ping(1).status == "no-echo" and bank.ping(1).range_m == 4.0
    near.range_cm = 15
    assert bank.ping(0).range_m == pytest.approx(0.15)


def test_a_sonar_that_stays_deaf_reads_no_response(i2c_bus, srf02_class):
    i2c_bus.attach(0x70, srf02_class(busy_after_command=1000))
    ping = make_bank(i2c_bus, [0x70], retries=5).ping(0)
    assert (ping.status, ping.range_m) == ("no-response", 4.0)


def test_missing_sonar_names_bus_and_address(i2c_bus, srf02_class):
    i2c_bus.attach(0x70, srf02_class())
    with pytest.raises(HardwareError, match="no SRF02 answers on I2C bus 1 at 0x71"):
        make_bank(i2c_bus, [0x70, 0x71])


def test_hardware_fires_srf02s_in_the_staggered_order(
    mock_factory, i2c_bus, srf02_class, fake_mpu, bus_factory, write_config
):
    from robot.pi.config import load_pi_setup
    from robot.pi.hardware import PiHardware

    setup = load_pi_setup(write_config(robot_pi_toml(sonar_ring=srf02_ring())))
    sonars = [i2c_bus.attach(0x70 + i, srf02_class(range_cm=100 + 10 * i)) for i in range(8)]
    with PiHardware.from_config(setup, bus_factory=bus_factory, sleep=lambda s: None) as hw:
        i2c_bus.log.clear()
        sweep = hw.read_sonar_sweep()
    assert sweep.ranges_m.tolist() == pytest.approx([1.0 + 0.1 * i for i in range(8)])
    commands = [address - 0x70 for op, address, register in i2c_bus.log if op == "write" and address >= 0x70]
    assert commands == [0, 4, 2, 6, 1, 5, 3, 7]
    assert all(s.commands == 1 for s in sonars)
    assert bus_factory.opened == [1]  # the IMU and the sonars share one bus
    assert i2c_bus.closed
