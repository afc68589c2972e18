"""HC-SR04 bank on gpiozero mock pins and the ring's firing schedule."""

from __future__ import annotations

import itertools

import pytest
from gpiozero.pins.mock import MockTriggerPin

from robot.pi.hcsr04 import HcSr04Bank
from robot.pi.sonar import Ping, SonarRing

TOLERANCE_M = 0.05  # MockTriggerPin times the echo with real sleeps


def test_echo_width_becomes_range_with_real_mock_timing(mock_factory, echo_time):
    echo = mock_factory.pin(17)
    mock_factory.pin(4, pin_class=MockTriggerPin, echo_pin=echo, echo_time=echo_time(1.2))
    bank = HcSr04Bank([4], [17], max_range_m=4.0)
    try:
        pings = [bank.ping(0) for _ in range(7)]
    finally:
        bank.close()
    assert all(p.status == "echo" for p in pings)
    # A late thread wake-up only ever lengthens the mock's pulse: the shortest reading is the fair one.
    assert min(p.range_m for p in pings) == pytest.approx(1.2, abs=TOLERANCE_M)


def test_exactly_timed_echo_gives_the_exact_range(mock_factory, hcsr04):
    hcsr04(mock_factory, 4, 17, 2.345)
    bank = HcSr04Bank([4], [17], max_range_m=4.0, speed_of_sound_m_s=343.0)
    try:
        assert bank.ping(0).range_m == pytest.approx(2.345, abs=1e-6)
    finally:
        bank.close()


def test_no_echo_reads_max_range_without_waiting_for_the_38ms_pulse(mock_factory):
    echo = mock_factory.pin(17)
    mock_factory.pin(4, pin_class=MockTriggerPin, echo_pin=echo, echo_time=0.06)
    bank = HcSr04Bank([4], [17], max_range_m=4.0)
    try:
        assert bank.echo_timeout_s < 0.038  # shorter than the module's own "nothing heard" pulse
        assert bank.ping(0) == Ping(4.0, "no-echo")
    finally:
        bank.close()


def test_a_silent_sensor_is_no_response(mock_factory):
    bank = HcSr04Bank([4], [17], max_range_m=4.0)  # plain pins: the echo never rises
    try:
        assert bank.ping(0) == Ping(4.0, "no-response")
    finally:
        bank.close()


def test_shared_echo_pin_serves_every_trigger(mock_factory, hcsr04, echo_time):
    triggers = [hcsr04(mock_factory, trigger, 17, 1.0) for trigger in (4, 27, 23)]  # one echo line
    bank = HcSr04Bank([4, 27, 23], [17, 17, 17], max_range_m=4.0)
    try:
        ranges = []
        for i, range_m in ((2, 1.5), (0, 0.4), (1, 0.9)):
            triggers[i].echo_time = triggers[i].echo_pin.width_s = echo_time(range_m)
            ranges.append(bank.ping(i).range_m)
    finally:
        bank.close()
    assert ranges == pytest.approx([1.5, 0.4, 0.9], abs=1e-6)


def test_close_is_idempotent_and_frees_the_pins(mock_factory):
    bank = HcSr04Bank([4], [17], max_range_m=4.0)
    bank.close()
    bank.close()
    HcSr04Bank([4], [17], max_range_m=4.0).close()  # the pins can be claimed again


class FakeBank:
    """A bank whose pings take 10 ms of fake clock time."""

    def __init__(self, clock) -> None:
        self.clock = clock
        self.pinged: list[tuple[int, float]] = []

    def __len__(self) -> int:
        return 8

    def ping(self, index: int) -> Ping:
        self.pinged.append((index, self.clock.now))
        self.clock.now += 0.010
        return Ping(0.5 + index, "echo" if index != 3 else "no-echo")

    def close(self) -> None:
        pass


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


def test_ring_fires_in_order_with_a_gap_between_pings_across_sweeps():
    clock = FakeClock()
    bank = FakeBank(clock)
    pings: list[int] = []
    ring = SonarRing(
        bank, (0, 4, 2, 6, 1, 5, 3, 7), 0.06, 4.0, clock=clock, sleep=clock.sleep, on_ping=lambda: pings.append(1)
    )
    first = ring.sweep()
    ring.sweep()
    order = [index for index, _ in bank.pinged]
    assert order == [0, 4, 2, 6, 1, 5, 3, 7] * 2
    starts = [t for _, t in bank.pinged]
    gaps = [b - a for a, b in itertools.pairwise(starts)]
    assert min(gaps) == pytest.approx(0.06)  # also between the last ping of a sweep and the next first
    assert first.tolist() == [0.5, 1.5, 2.5, 3.5, 4.0, 4.0, 4.0, 4.0]  # clipped to max range, mounting order
    assert ring.last_status[3] == "no-echo"
    assert len(pings) == 16  # the watchdog hook runs after every ping


def test_ring_rejects_a_bad_firing_order():
    with pytest.raises(ValueError, match="must list each of the 8 sensors once"):
        SonarRing(FakeBank(FakeClock()), (0, 1, 2), 0.06, 4.0)


def test_hardware_sweep_in_mounting_order_fired_in_staggered_order(robot_hw, sonar_pins):
    fired: list[int] = []
    for i, pin in enumerate(sonar_pins):
        original = pin._set_state

        def recording(value, i=i, original=original):
            if value:
                fired.append(i)
            original(value)

        pin._set_state = recording
    sweep = robot_hw.read_sonar_sweep()
    assert fired == [0, 4, 2, 6, 1, 5, 3, 7]
    assert sweep.ranges_m.shape == (8,)
    assert sweep.ranges_m.tolist() == pytest.approx([0.5 + 0.1 * i for i in range(8)], abs=1e-6)
    assert sweep.t_s <= robot_hw.now()
