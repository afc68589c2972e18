"""MPU-6050 driver against a fake register map: identity, set-up, units, signs, calibration, sampling."""

from __future__ import annotations

import math

import pytest

from robot.errors import HardwareError
from robot.pi.mpu6050 import ImuSampler, Mpu6050

G = 9.80665


def make_imu(bus, **kwargs) -> Mpu6050:
    return Mpu6050(bus, bus_number=1, sleep=lambda s: None, **kwargs)


def test_missing_imu_names_bus_and_address(i2c_bus):
    with pytest.raises(HardwareError, match="no device answers: IMU on I2C bus 1 at 0x68"):
        make_imu(i2c_bus)


def test_wrong_chip_names_bus_address_and_identity(i2c_bus, fake_mpu):
    fake_mpu.registers[0x75] = 0x70  # an MPU-6500
    with pytest.raises(HardwareError, match="IMU on I2C bus 1 at 0x68: WHO_AM_I reads 0x70, expected 0x68"):
        make_imu(i2c_bus)


def test_set_up_wakes_the_chip_and_selects_ranges(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus, sample_rate_hz=100.0)
    assert imu.who_am_i == 0x68
    writes = dict(fake_mpu.writes)
    assert writes[0x6B] in (0x00, 0x01)  # awake
    assert writes[0x1A] == 3  # DLPF about 42 Hz
    assert writes[0x1B] == 0  # +-250 deg/s
    assert writes[0x1C] == 0  # +-2 g
    assert writes[0x19] == 9  # 1 kHz / (1 + 9) = 100 Hz


def test_one_14_byte_burst_per_sample(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus)
    fake_mpu.block_reads.clear()
    imu.read_raw()
    assert fake_mpu.block_reads == [(0x3B, 14)]


def test_positive_chip_z_rate_is_counter_clockwise_yaw(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus)
    fake_mpu.set_raw(accel=(16384, -8192, 16384), gyro=(0, 0, 131))  # 1 deg/s about +z
    sample = imu.to_sample(imu.read_raw(), t_s=12.5)
    assert sample.t_s == 12.5
    assert sample.gyro_z_rad_s == pytest.approx(math.radians(1.0))
    assert sample.accel_x_m_s2 == pytest.approx(G)  # +1 g forward
    assert sample.accel_y_m_s2 == pytest.approx(-G / 2)


def test_full_scale_gyro_is_250_deg_per_s(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus)
    fake_mpu.set_raw(gyro=(0, 0, -32768))
    assert imu.to_sample(imu.read_raw(), 0.0).gyro_z_rad_s == pytest.approx(-math.radians(32768 / 131.0))


def test_upside_down_mounting_flips_yaw_and_left(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus, forward_axis="+x", left_axis="-y", up_axis="-z")
    fake_mpu.set_raw(accel=(0, 8192, -16384), gyro=(0, 0, 131))
    sample = imu.to_sample(imu.read_raw(), 0.0)
    assert sample.gyro_z_rad_s == pytest.approx(-math.radians(1.0))  # chip +z points down
    assert sample.accel_y_m_s2 == pytest.approx(-G / 2)


def test_calibration_removes_the_gyro_bias(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus)
    fake_mpu.set_raw(accel=(0, 0, 16384), gyro=(10, -20, 50))
    calibration = imu.calibrate(50, 0.01, sleep=lambda s: None)
    assert calibration.bias_counts == (10.0, -20.0, 50.0)
    assert calibration.yaw_bias_dps == pytest.approx(50 / 131.0)
    assert calibration.gravity_up_g == pytest.approx(1.0)
    assert calibration.yaw_std_dps == pytest.approx(0.0, abs=1e-9)
    fake_mpu.set_raw(accel=(0, 0, 16384), gyro=(10, -20, 50 + 131))
    assert imu.to_sample(imu.read_raw(), 0.0).gyro_z_rad_s == pytest.approx(math.radians(1.0))


def test_calibration_refuses_a_moving_robot(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus)
    fake_mpu.queue.extend(((0, 0, 16384), 0, (0, 0, 500 * (-1) ** i)) for i in range(20))
    with pytest.raises(HardwareError, match="the robot moved during gyro calibration"):
        imu.calibrate(20, 0.01, sleep=lambda s: None)


def test_calibration_spots_an_upside_down_board(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus)
    fake_mpu.set_raw(accel=(0, 0, -16384))
    with pytest.raises(HardwareError, match=r"gravity reads -1.00 g along up_axis='\+z'.*try up_axis = '-z'"):
        imu.calibrate(20, 0.01, sleep=lambda s: None)


def test_sampler_buffers_timestamped_samples_until_drained(i2c_bus, fake_mpu):
    imu = make_imu(i2c_bus)
    ticks = iter(range(100))
    sampler = ImuSampler(imu, rate_hz=100.0, clock=lambda: float(next(ticks)))
    fake_mpu.queue.extend(((0, 0, 16384), 0, (0, 0, 131 * k)) for k in (1, 2, 3))
    for _ in range(3):
        sampler.poll()
    samples = sampler.drain()
    assert [s.t_s for s in samples] == [0.5, 2.5, 4.5]  # midpoint of each transfer
    assert [round(math.degrees(s.gyro_z_rad_s)) for s in samples] == [1, 2, 3]
    assert sampler.drain() == []


def test_sampler_thread_samples_at_its_rate(i2c_bus, fake_mpu, eventually):
    sampler = ImuSampler(make_imu(i2c_bus), rate_hz=500.0).start()
    try:
        collected = []
        assert eventually(lambda: collected.extend(sampler.drain()) or len(collected) >= 5)
        times = [s.t_s for s in collected]
        assert times == sorted(times)
    finally:
        sampler.close()


def test_sampler_reports_a_dead_bus(i2c_bus, fake_mpu):
    sampler = ImuSampler(make_imu(i2c_bus), rate_hz=100.0)
    del i2c_bus.devices[0x68]
    for _ in range(ImuSampler.MAX_CONSECUTIVE_ERRORS):
        assert sampler.poll() is None
    with pytest.raises(HardwareError, match="IMU on I2C bus 1 at 0x68: 50 reads failed in a row"):
        sampler.drain()
