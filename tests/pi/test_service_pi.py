"""``sonarslam serve --hardware pi``: the real service drives PiHardware on mock pins and a fake I2C bus.

The service runs in this process (uvicorn on a thread, an ephemeral 127.0.0.1 port) so that gpiozero's
mock pin factory and the fake bus can stand in for the Pi. Behind them the simulator moves the robot
(``sim_bridge.py``): the motors' PWM duties drive it, its wheels tick the encoder pins, its sonar
ranges and gyro rates answer on the bus. Only how the devices are opened is swapped
(``server.hardware.open_pi``); loading the wiring, the safety guard, the run thread and the
SLAM engine are the service's own.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import live_client
import numpy as np
import pytest
from live_client import Viewer, csv_codes, run_async, watch
from live_server import LiveServer, isolated_settings
from pi_configs import MOTOR_PINS, sim_pi_toml
from sim_bridge import SimBridge

import server.hardware as service_hardware
import server.run_body as run_body
from robot.errors import HardwareError
from robot.pi.config import PiSetup
from robot.pi.hardware import PiHardware
from robot.runner import frame_for_unknown_room
from robot.settings import load_run_config
from robot.sim import SimRobot
from robot.world import load_world

WORLD = "room2"  # the room the simulated robot stands in; the service sees an unknown room
RUN = {"mapper": "logodds", "seed": 0}  # what a client sends for a robot run: no world, no speed
TIMEOUT_S = 60.0
WATCHDOG_THREAD = "sonarslam-watchdog"


@dataclass
class BridgedRobot:
    """Stands in for ``server.hardware.open_pi``: every run gets a fresh simulator behind the same mock pins."""

    factory: Any
    mpu_class: type
    srf02_class: type
    bus_class: type
    who_am_i: int | None = None  # set to make the IMU answer as some other chip
    bridges: list[SimBridge] = field(default_factory=list)
    # Set ``stall``: the next sleep while the wheels turn blocks the run thread until ``release``.
    stall: threading.Event = field(default_factory=threading.Event)
    stalled: threading.Event = field(default_factory=threading.Event)
    release: threading.Event = field(default_factory=threading.Event)
    stalled_command: tuple[float, float] | None = None  # the wheel command on the pins when it stalled

    def open(self, setup: PiSetup) -> PiHardware:
        cfg = load_run_config()
        sim = SimRobot(load_world(WORLD), cfg.robot, cfg.noise, seed=len(self.bridges))
        bridge = SimBridge(
            sim, setup, self.factory, bus=self.bus_class(1), mpu_class=self.mpu_class, srf02_class=self.srf02_class
        )
        if self.who_am_i is not None:
            bridge.mpu.registers[0x75] = self.who_am_i
        self.bridges.append(bridge)
        hw = PiHardware.from_config(
            setup,
            pin_factory=self.factory,
            bus_factory=bridge.open_bus,
            clock=bridge.now,
            sleep=self._sleep(bridge),
            start_imu=False,  # the bridge samples the IMU at each simulated gyro sample
        )
        bridge.hw = hw
        bridge.attach_encoders()
        return hw

    def _sleep(self, bridge: SimBridge) -> Callable[[float], None]:
        def sleep(duration_s: float) -> None:
            if self.stall.is_set() and bridge.wheel_command() != (0.0, 0.0):
                self.stall.clear()
                self.stalled_command = bridge.wheel_command()
                self.stalled.set()
                self.release.wait(TIMEOUT_S)  # a control loop stuck in a slow call, in real time
            bridge.sleep(duration_s)

        return sleep

    @property
    def hw(self) -> PiHardware:
        assert self.bridges and self.bridges[-1].hw is not None, "the service has not opened the robot"
        hw: PiHardware = self.bridges[-1].hw
        return hw

    def driven(self) -> bool:
        """Whether the service has commanded the wheels to turn (read back from the PWM pins)."""
        return any(command != (0.0, 0.0) for bridge in self.bridges for command in bridge.commands)


@dataclass
class PiService:
    live: LiveServer
    robot: BridgedRobot
    api: httpx.Client


@pytest.fixture
def robot(mock_factory, mpu_class, srf02_class, i2c_bus_class, monkeypatch) -> BridgedRobot:
    bridged = BridgedRobot(mock_factory, mpu_class, srf02_class, i2c_bus_class)
    monkeypatch.setattr(service_hardware, "open_pi", bridged.open)
    return bridged


@pytest.fixture
def start_service(tmp_path: Path) -> Iterator[Any]:
    """``start_service(pi_config_file)``: the service with ``hardware = "pi"``; stopped after the test."""
    started: list[LiveServer] = []
    clients: list[httpx.Client] = []

    def start(pi_config_file: Path | None) -> tuple[LiveServer, httpx.Client]:
        settings = isolated_settings(tmp_path / "data", hardware="pi", pi_config_file=pi_config_file)
        live = LiveServer(settings).start()
        started.append(live)
        clients.append(live.client())
        return live, clients[-1]

    yield start
    for client in clients:
        client.close()
    for live in started:
        live.stop()


@pytest.fixture
def service(robot: BridgedRobot, start_service: Any, tmp_path: Path) -> PiService:
    config = tmp_path / "robot-pi.toml"
    config.write_text(sim_pi_toml())
    live, api = start_service(config)
    return PiService(live, robot, api)


MOTORS_OFF = {"left": (0.0, 0.0), "right": (0.0, 0.0)}


def start_run(api: httpx.Client, **options: Any) -> dict[str, Any]:
    response = api.post("/api/runs", json={**RUN, **options})
    assert response.status_code == 201, response.text
    return dict(response.json())


def wait_ended(api: httpx.Client, run_id: str, timeout_s: float = TIMEOUT_S) -> dict[str, Any]:
    return live_client.wait_ended(api, run_id, timeout_s)


def watchdog_running() -> bool:
    return any(t.name == WATCHDOG_THREAD and t.is_alive() for t in threading.enumerate())


def mapped_floor_and_walls(viewer: Viewer) -> bool:
    """The viewer's map shows free floor and walls (an unknown room stays grey for the first few steps)."""
    return viewer.steps >= 3 and viewer.grid is not None and bool((viewer.grid == 0).any() and (viewer.grid == 1).any())


class BackgroundViewer:
    """A protocol-following viewer on its own thread, watching a run until the service closes the socket."""

    def __init__(self, url: str, ready: Callable[[Viewer], bool]) -> None:
        self.ready = threading.Event()  # set once ``ready(viewer)`` has held
        self.result: dict[str, Any] = {}

        async def on_message(viewer: Viewer, msg: dict[str, Any], ws: Any) -> None:
            if ready(viewer):
                self.ready.set()

        def target() -> None:
            try:
                self.result["viewer"] = run_async(watch(url, timeout_s=TIMEOUT_S, on_message=on_message))
            except BaseException as exc:
                self.result["error"] = exc
                self.ready.set()

        self.thread = threading.Thread(target=target, daemon=True)
        self.thread.start()

    def join(self) -> Viewer:
        self.thread.join(TIMEOUT_S)
        assert not self.thread.is_alive(), "the viewer did not finish"
        if "error" in self.result:
            raise self.result["error"]
        viewer: Viewer = self.result["viewer"]
        return viewer


def test_a_robot_run_streams_stops_and_leaves_the_motors_off(
    service: PiService, motor_states: Any, eventually: Any
) -> None:
    api, robot, live = service.api, service.robot, service.live
    run = start_run(api, world="room1", max_steps=5000)  # a world means nothing to a robot: it is dropped
    run_id = run["id"]
    assert run["hardware"] == "pi" and run["world"] is None and run["status"] in ("queued", "running")

    # One robot, one run: a second start is refused, not queued.
    second = api.post("/api/runs", json=RUN)
    assert second.status_code == 409 and f"busy with run {run_id}" in second.json()["detail"]

    viewer_thread = BackgroundViewer(f"{live.ws_url}/ws/runs/{run_id}", ready=mapped_floor_and_walls)
    assert viewer_thread.ready.wait(TIMEOUT_S), "the stream never showed a map"
    assert api.get(f"/api/runs/{run_id}").json()["status"] == "running"
    assert eventually(robot.driven, TIMEOUT_S), "the wheels were never commanded"
    assert watchdog_running()  # the safety guard is on while the robot runs

    stopped = api.post(f"/api/runs/{run_id}/stop")
    assert stopped.status_code == 200, stopped.text
    body = stopped.json()
    assert body["status"] == "stopped" and body["terminated_by"] == "stopped" and body["error"] is None
    assert body["metrics"] is None and body["progress"]["step"] >= 3  # an unknown room has no truth to score
    assert motor_states() == MOTORS_OFF
    with pytest.raises(HardwareError, match="closed"):
        robot.hw.set_wheel_speeds(0.1, 0.1)  # released: nothing drives the pins any more
    assert eventually(lambda: not watchdog_running())

    viewer = viewer_thread.join()
    assert viewer.hello is not None and viewer.hello["run_id"] == run_id
    assert viewer.close_code == 1000 and viewer.snapshots == 1 and viewer.resyncs == 0
    snapshot = viewer.last_snapshot
    assert snapshot is not None and snapshot["run"]["hardware"] == "pi" and snapshot["truth"] is None
    slam = load_run_config().slam
    grid = frame_for_unknown_room(slam.resolution, slam.unknown_room_size_m).grid  # centred on the start
    assert (snapshot["grid"]["rows"], snapshot["grid"]["cols"]) == (grid.rows, grid.cols)
    final = viewer.final_status
    assert final is not None and final["event"] == "stopped" and viewer.steps >= 3

    # The partial map downloads, and it is the map the viewer rebuilt from the stream.
    response = api.get(f"/api/runs/{run_id}/map.csv")
    assert response.status_code == 200
    saved = csv_codes(response.text)
    assert saved.shape == (grid.rows, grid.cols)
    assert (saved == 0).any() and (saved == 1).any()  # it mapped free floor and walls
    assert viewer.grid is not None and np.array_equal(viewer.grid, saved)

    # The robot is free again.
    again = start_run(api)
    assert api.post(f"/api/runs/{again['id']}/stop").json()["status"] == "stopped"
    assert motor_states() == MOTORS_OFF


def test_an_imu_that_is_not_an_mpu6050_ends_the_run_as_error(
    service: PiService, motor_states: Any, caplog: pytest.LogCaptureFixture
) -> None:
    api, robot, live = service.api, service.robot, service.live
    robot.who_am_i = 0x71  # an MPU-9250 answers at the same address
    run_id = start_run(api)["id"]
    run = wait_ended(api, run_id)
    assert run["status"] == "error" and run["terminated_by"] == "error"
    error = run["error"]
    assert "WHO_AM_I reads 0x71, expected 0x68" in error and "\n" not in error and "Traceback" not in error
    # The service log says it in one line too: an expected failure is not a crash with a traceback.
    failed = [r for r in caplog.records if r.name == "sonarslam.server" and f"run {run_id} failed" in r.getMessage()]
    assert failed and all(r.exc_info is None for r in failed) and "WHO_AM_I" in failed[0].getMessage()

    viewer = run_async(watch(f"{live.ws_url}/ws/runs/{run_id}", timeout_s=TIMEOUT_S))
    assert viewer.final_status is not None and viewer.final_status["event"] == "error"
    assert "WHO_AM_I" in viewer.final_status["message"]
    assert api.get(f"/api/runs/{run_id}/map.csv").status_code == 200  # an empty map, but a map

    # Whatever was opened before the IMU failed is released again, with the motors off.
    bridge = robot.bridges[-1]
    assert bridge.bus.closed
    assert motor_states() == MOTORS_OFF
    from gpiozero import Motor

    Motor(*MOTOR_PINS["left"]).close()  # nothing holds the motor pins any more

    robot.who_am_i = None  # with the right chip, the robot can start again
    again = start_run(api)
    assert api.post(f"/api/runs/{again['id']}/stop").json()["status"] == "stopped"


def test_a_stop_while_the_run_sets_up_its_engine_ends_as_stopped(
    service: PiService, motor_states: Any, eventually: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The stop halts the hardware after it has opened and before the engine has read it: the engine's
    first hardware call fails, and that is the stop, not an error."""
    api, robot = service.api, service.robot
    real_engine = run_body.SlamEngine
    setting_up = threading.Event()

    def engine_after_the_stop(hw: Any, *args: Any, **kwargs: Any) -> Any:
        setting_up.set()
        assert eventually(lambda: hw.halted is not None, TIMEOUT_S), "the stop never halted the hardware"
        return real_engine(hw, *args, **kwargs)

    monkeypatch.setattr(run_body, "SlamEngine", engine_after_the_stop)
    run_id = start_run(api)["id"]
    assert setting_up.wait(TIMEOUT_S), "the run never set up its engine"
    assert api.post(f"/api/runs/{run_id}/stop").json()["status"] == "stopped"
    run = wait_ended(api, run_id)
    assert (run["status"], run["terminated_by"], run["error"]) == ("stopped", "stopped", None), run
    assert robot.hw.halted == "run stopped"
    assert motor_states() == MOTORS_OFF


def stall_while_driving(service: PiService, eventually: Any) -> str:
    """Start a run and hold its thread inside a hardware call while the wheels are driven; the caller
    lets it go with ``service.robot.release.set()``."""
    api, robot = service.api, service.robot
    run_id = str(start_run(api, max_steps=5000)["id"])
    assert eventually(robot.driven, TIMEOUT_S), "the wheels were never commanded"
    robot.stall.set()
    try:
        assert robot.stalled.wait(TIMEOUT_S), "the run never stalled"
        assert robot.stalled_command is not None and robot.stalled_command != (0.0, 0.0)  # stuck while driving
    except BaseException:
        robot.release.set()  # never leave the run thread stuck
        raise
    return run_id


def test_the_watchdog_stops_the_wheels_while_the_run_thread_is_stuck(
    service: PiService, motor_states: Any, eventually: Any
) -> None:
    api, robot = service.api, service.robot
    run_id = stall_while_driving(service, eventually)
    try:
        commands = robot.bridges[-1].commands  # the wheel commands seen on the pins, appended at every change
        seen = len(commands)

        # Nothing calls the hardware now; after safety.watchdog_timeout_s (0.5 s) the wheels stop.
        assert eventually(lambda: motor_states() == MOTORS_OFF, 10.0), "the watchdog did not stop the wheels"
        run = api.get(f"/api/runs/{run_id}").json()
        assert run["status"] == "running"
    finally:
        robot.release.set()  # never leave the run thread stuck

    # The loop goes on, and the wheels turn again once it commands them again.
    assert eventually(lambda: any(c != (0.0, 0.0) for c in commands[seen:]), TIMEOUT_S)
    step = run["progress"]["step"]
    assert eventually(lambda: api.get(f"/api/runs/{run_id}").json()["progress"]["step"] > step, TIMEOUT_S)
    assert api.post(f"/api/runs/{run_id}/stop").json()["status"] == "stopped"
    assert motor_states() == MOTORS_OFF


@pytest.mark.filterwarnings("ignore::gpiozero.exc.PinFactoryFallback")  # gpiozero trying each library in turn
@pytest.mark.usefixtures("no_pin_factory")
def test_without_a_gpio_pin_factory_the_run_ends_as_error(start_service: Any) -> None:
    """The shipped config/robot-pi.toml through the real ``open_pi``, on a machine that is not a Pi."""
    _live, api = start_service(None)
    run_id = start_run(api)["id"]
    run = wait_ended(api, run_id)
    assert run["status"] == "error" and run["hardware"] == "pi"
    assert "no GPIO pin factory" in run["error"] and "GPIOZERO_PIN_FACTORY=mock" in run["error"]
    assert "\n" not in run["error"]


def test_a_stop_in_the_middle_of_a_move_halts_the_wheels_at_once_and_ends_as_stopped(
    service: PiService, motor_states: Any, eventually: Any
) -> None:
    api, robot = service.api, service.robot
    run_id = stall_while_driving(service, eventually)
    answers: list[httpx.Response] = []
    stopper = threading.Thread(target=lambda: answers.append(api.post(f"/api/runs/{run_id}/stop")))
    try:
        stopper.start()
        # The stop itself halts the motors, while the step is still under way (not the watchdog).
        assert eventually(lambda: robot.hw.halted == "run stopped", TIMEOUT_S), robot.hw.halted
        assert motor_states() == MOTORS_OFF
    finally:
        robot.release.set()
    stopper.join(TIMEOUT_S)
    assert answers and answers[0].status_code == 200, answers
    run = wait_ended(api, run_id)
    assert (run["status"], run["terminated_by"], run["error"]) == ("stopped", "stopped", None), run
    assert api.get(f"/api/runs/{run_id}/map.csv").status_code == 200
    assert motor_states() == MOTORS_OFF


def test_sigterm_halts_the_robot_at_once_and_the_run_ends(
    service: PiService, motor_states: Any, eventually: Any, tmp_path: Path
) -> None:
    api, robot, live = service.api, service.robot, service.live
    run_id = start_run(api, max_steps=5000)["id"]
    assert eventually(lambda: robot.bridges and robot.driven(), TIMEOUT_S), "the wheels were never commanded"

    live.server.handle_exit(signal.SIGTERM, None)  # what uvicorn's handler runs on the main thread

    assert robot.hw.halted == "stopped by SIGTERM"
    assert eventually(lambda: motor_states() == MOTORS_OFF)
    live.thread.join(TIMEOUT_S)
    assert not live.thread.is_alive(), "the service did not shut down"
    with pytest.raises(HardwareError):
        robot.hw.set_wheel_speeds(0.1, 0.1)

    # The run recorded its own end before the service went (not the restart's crash recovery), as
    # interrupted whether it was between steps or cut off mid-step.
    restarted = LiveServer(isolated_settings(tmp_path / "data", hardware="pi")).start()
    try:
        with restarted.client() as client:
            run = client.get(f"/api/runs/{run_id}").json()
    finally:
        restarted.stop()
    assert (run["status"], run["terminated_by"]) == ("interrupted", "shutdown"), run
    assert run["error"] is None
