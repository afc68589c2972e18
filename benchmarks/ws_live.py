"""Live map streaming: WebSocket bytes vs resending the grid, pose latency, and the cost of many viewers.

Starts ``sonarslam serve`` as its own process on an ephemeral 127.0.0.1 port (so viewers and service do
not share an interpreter) and prints three measurements:

1. bytes: everything one viewer receives during a whole run, against the same messages carrying
   the full grid at every step instead of the changed cells (target: <= 5 %); once as plain text (a
   viewer that does not offer compression, or any viewer at the default settings) and once with
   permessage-deflate (what browsers negotiate when the service offers it: setting ``ws_compression``,
   off by default);
2. latency: step end on the server (``wall_time``, which steps carry for viewers that ask with
   ``?timing=1``) to arrival at a viewer, p50 / p99, with 1 and 50 viewers (target: p99 < 50 ms on loopback);
3. slowdown: wall time of a max-speed run with 50 viewers against none (target: < 10 %).

Latency and slowdown use the service's default settings unless ``--ws-compression`` says otherwise; their
viewers offer permessage-deflate as browsers do, so the service compresses for every one of them.

    python benchmarks/ws_live.py [--only bytes|latency|slowdown] [--world room1] [--viewers 50]
                                 [--repeats 5] [--ws-compression true|false]
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import json
import os
import queue
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from websockets.asyncio.client import connect
from websockets.extensions.base import Extension
from websockets.extensions.permessage_deflate import ClientPerMessageDeflateFactory, PerMessageDeflate
from websockets.frames import CTRL_OPCODES, Frame

from server.settings import ServerSettings

URL_LINE = re.compile(r"(http://127\.0\.0\.1:\d+)/")


def _stat(path: str) -> list[str]:
    return Path(path).read_text().rsplit(")", 1)[1].split()  # fields from the state on (the name may hold spaces)


def cpu_seconds(pid: int, main_thread_only: bool = False) -> float:
    """User + system CPU time of a process (or of its main thread: the service's event loop) so far."""
    fields = _stat(f"/proc/{pid}/task/{pid}/stat" if main_thread_only else f"/proc/{pid}/stat")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def context_switches(pid: int) -> int:
    """How often the service's main thread (its event loop) has been switched out so far: each time it
    slept and woke, or waited for the interpreter lock, or was preempted."""
    status = Path(f"/proc/{pid}/task/{pid}/status").read_text().splitlines()
    return sum(int(line.split()[1]) for line in status if line.split(":")[0].endswith("ctxt_switches"))


def children_of() -> dict[int, list[int]]:
    """Every process's children, from /proc."""
    out: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError):  # gone meanwhile
                out.setdefault(int(_stat(f"/proc/{entry.name}/stat")[1]), []).append(int(entry.name))
    return out


def tree_cpu_seconds(pid: int, children: dict[int, list[int]] | None = None) -> float:
    """CPU time of a process and all its descendants so far: the service, its forkserver and the runs' engine
    processes. An ended child's time is in its parent's (once reaped), a live one's is its own."""
    children = children_of() if children is None else children
    try:
        fields = _stat(f"/proc/{pid}/stat")
    except OSError:
        return 0.0  # ended meanwhile: its parent will count it
    own = sum(int(v) for v in fields[11:15]) / os.sysconf("SC_CLK_TCK")  # utime, stime, cutime, cstime
    return own + sum(tree_cpu_seconds(child, children) for child in children.get(pid, ()))


def wait_engines_reaped(pid: int, timeout_s: float = 10.0) -> None:
    """Until no grandchild of the service is left (the engine process of a run that has just ended)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        children = children_of()
        if not any(children.get(child) for child in children.get(pid, ())):
            return
        time.sleep(0.01)


SERVICE_PID: list[int] = []  # the running service's process id, for cpu_seconds()


@contextmanager
def service(data_dir: Path, **settings: str) -> Iterator[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SONARSLAM_")}
    env |= {"SONARSLAM_LOG_LEVEL": "warning", "SONARSLAM_MAX_CONCURRENT_RUNS": "1"}
    env |= {f"SONARSLAM_{k.upper()}": v for k, v in settings.items()}
    cmd = [sys.executable, "-m", "robot", "serve", "--port", "0", "--data-dir", str(data_dir)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in proc.stdout or ()], daemon=True).start()
    SERVICE_PID[:] = [proc.pid]
    try:
        url = None
        while url is None:
            match = URL_LINE.search(lines.get(timeout=30))
            url = match.group(1) if match else None
        deadline = time.monotonic() + 30
        while True:
            try:
                if httpx.get(f"{url}/api/health", timeout=5).status_code == 200:
                    break
            except httpx.TransportError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        yield url
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()


def start_run(url: str, world: str, **options: Any) -> str:
    body = {"world": world, "speed": "max", "seed": 0, **options}
    response = httpx.post(f"{url}/api/runs", json=body, timeout=30)
    response.raise_for_status()
    return str(response.json()["id"])


def queued_run(url: str, world: str, **options: Any) -> str:
    """A run that waits behind a short one (one slot): viewers connecting now see it from its first step."""
    start_run(url, "room2", speed=0.5, max_steps=1)
    run_id = start_run(url, world, **options)
    assert httpx.get(f"{url}/api/runs/{run_id}", timeout=30).json()["status"] == "queued"
    return run_id


def wait_ended(url: str, run_id: str, timeout_s: float = 900.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        run = httpx.get(f"{url}/api/runs/{run_id}", timeout=30).json()
        if run["status"] not in ("queued", "running"):
            return dict(run)
        time.sleep(0.25)
    raise TimeoutError(run_id)


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if values else float("nan")


# -- 1. bytes --------------------------------------------------------------------------------------
class CountingDeflate(Extension):
    """permessage-deflate as negotiated, counting the payload bytes of data frames as they arrive."""

    def __init__(self, inner: PerMessageDeflate) -> None:
        self.inner = inner
        self.name = inner.name
        self.received = 0

    def decode(self, frame: Frame, *, max_size: int | None = None) -> Frame:
        if frame.opcode not in CTRL_OPCODES:
            self.received += len(frame.data)
        return self.inner.decode(frame, max_size=max_size)

    def encode(self, frame: Frame) -> Frame:
        return self.inner.encode(frame)


class CountingDeflateFactory(ClientPerMessageDeflateFactory):
    """What ``compression="deflate"`` asks for (websockets' defaults), with the bytes counted."""

    extension: CountingDeflate | None = None

    def __init__(self) -> None:
        super().__init__(compress_settings={"memLevel": 5})

    def process_response_params(self, params: Any, accepted_extensions: Any) -> CountingDeflate:
        inner = super().process_response_params(params, accepted_extensions)
        assert isinstance(inner, PerMessageDeflate)
        self.extension = CountingDeflate(inner)
        return self.extension


class Deflater:
    """The server's side of permessage-deflate (context takeover), run here over messages it never sent."""

    def __init__(self, window_bits: int) -> None:
        self.z = zlib.compressobj(wbits=-window_bits, memLevel=5)

    def size(self, text: str) -> int:
        return len(self.z.compress(text.encode()) + self.z.flush(zlib.Z_SYNC_FLUSH)) - 4


def encode(message: dict[str, Any]) -> str:
    return json.dumps(message, separators=(",", ":"))


async def count_bytes(ws_url: str, deflate: bool) -> dict[str, int]:
    """Receive a whole run; size every message, and the same messages carrying the full grid at every step.

    The baseline is built message by message: each step as received, but with its cell changes (if
    any) replaced by the whole grid, once for every engine step it stands for; everything else as is."""
    totals = dict.fromkeys(("messages", "ours", "wire", "steps", "merged", "step_cells", "grid"), 0)
    totals |= dict.fromkeys(("full_b64", "full_json", "ours_deflated", "full_b64_deflated"), 0)
    grid: np.ndarray | None = None
    factory = CountingDeflateFactory() if deflate else None
    extensions = [factory] if factory is not None else None
    ours_z: Deflater | None = None
    full_z: Deflater | None = None
    async with connect(ws_url, max_size=None, compression=None, extensions=extensions) as ws:
        if factory is not None:
            assert factory.extension is not None, "the service did not negotiate permessage-deflate"
            window = factory.extension.inner.remote_max_window_bits
            ours_z, full_z = Deflater(window), Deflater(window)
        async for raw in ws:
            text = raw.decode() if isinstance(raw, bytes) else raw
            size = len(text.encode())
            totals["messages"] += 1
            totals["ours"] += size
            msg = json.loads(text)
            baseline = [text]
            ros = text
            if msg["type"] == "snapshot":
                g = msg["grid"]
                cells = np.frombuffer(base64.b64decode(msg["cells"]), dtype=np.uint8)
                grid = cells.reshape(g["rows"], g["cols"]).copy()
                totals["grid"] = grid.size
            elif msg["type"] == "step" and grid is not None:
                changes = msg.get("cells", [])
                for r, c, code in changes:
                    grid[r, c] = code
                n = msg.get("merged", 1)  # the baseline resends the grid for every engine step
                totals["steps"] += n
                totals["merged"] += n - 1
                totals["step_cells"] += len(encode(changes)) if changes else 0
                baseline = [encode(msg | {"cells": base64.b64encode(grid.tobytes()).decode()})] * n
                ros_cells = np.where(grid == 2, -1, np.where(grid == 1, 100, 0)).ravel().tolist()  # rosbridge int8
                ros = encode(msg | {"cells": ros_cells})
                totals["full_json"] += (n - 1) * len(ros)
            totals["full_b64"] += sum(len(t) for t in baseline)
            totals["full_json"] += len(ros)
            if ours_z is not None and full_z is not None:
                totals["ours_deflated"] += ours_z.size(text)
                totals["full_b64_deflated"] += sum(full_z.size(t) for t in baseline)
    totals["wire"] = factory.extension.received if factory is not None and factory.extension else totals["ours"]
    return totals


def bench_bytes(url: str, world: str, resolutions: list[float]) -> None:
    print(f"\n1. bytes over the WebSocket for a whole {world} run, one viewer, vs the full grid at every step")
    for resolution in resolutions:
        for deflate in (False, True):
            run_id = queued_run(url, world, resolution=resolution)
            t = asyncio.run(count_bytes(f"{url.replace('http', 'ws')}/ws/runs/{run_id}", deflate))
            run = wait_ended(url, run_id)
            if not deflate:
                full_grid_b64 = t["steps"] * ((t["grid"] + 2) // 3 * 4)
                print(
                    f"   resolution {resolution} m ({t['grid']} cells), {t['steps']} steps ({run['terminated_by']}): "
                    f"{t['messages']} messages ({t['merged']} steps merged away)"
                )
                print(
                    f"     plain text: {t['ours'] / 1e3:.1f} kB vs {t['full_b64'] / 1e3:.1f} kB with the grid (base64) "
                    f"in every step = {100 * t['ours'] / t['full_b64']:.1f} %; vs {t['full_json'] / 1e3:.1f} kB "
                    f"as a rosbridge-style int array = {100 * t['ours'] / t['full_json']:.1f} %"
                )
                cells_kb, grids_kb = t["step_cells"] / 1e3, full_grid_b64 / 1e3
                print(
                    f"     map data only: {cells_kb:.1f} kB of cell changes vs {grids_kb:.1f} kB "
                    f"of full grids = {100 * t['step_cells'] / max(full_grid_b64, 1):.2f} %"
                )
            else:
                print(
                    f"     permessage-deflate: {t['wire'] / 1e3:.1f} kB on the wire ({t['ours'] / 1e3:.1f} kB of text, "
                    f"{t['messages']} messages; the server's compressor run here over the same text gives "
                    f"{t['ours_deflated'] / 1e3:.1f} kB)"
                )
                print(
                    f"       vs the plain-text full-grid baseline {t['full_b64'] / 1e3:.1f} kB = "
                    f"{100 * t['wire'] / t['full_b64']:.1f} %; vs that baseline deflated the same way "
                    f"{t['full_b64_deflated'] / 1e3:.1f} kB = {100 * t['wire'] / t['full_b64_deflated']:.1f} %"
                )


# -- 2. latency ------------------------------------------------------------------------------------
async def viewer_latencies(ws_url: str, out: list[float], counts: list[int], deflated: list[bool]) -> None:
    # compression="deflate" (websockets' default) offers permessage-deflate, as a browser does.
    async with connect(ws_url, max_size=None, max_queue=None) as ws:
        deflated.append(any(isinstance(ext, PerMessageDeflate) for ext in ws.protocol.extensions))
        n = 0
        async for raw in ws:
            now = time.time()
            if isinstance(raw, str) and raw.startswith('{"type":"step"'):
                at = raw.rfind('"wall_time":') + 12  # cheaper than parsing 50 copies of every message
                end = min(i for i in (raw.find(",", at), raw.find("}", at)) if i > 0)
                out.append(now - float(raw[at:end]))
                n += 1
        counts.append(n)


async def watch_many(ws_url: str, viewers: int) -> tuple[list[float], list[int], int]:
    """Every viewer's latencies, steps seen per viewer, and how many viewers got permessage-deflate."""
    latencies: list[float] = []
    counts: list[int] = []
    deflated: list[bool] = []
    await asyncio.gather(*(viewer_latencies(ws_url, latencies, counts, deflated) for _ in range(viewers)))
    return latencies, counts, sum(deflated)


def bench_latency(url: str, world: str, viewers: list[int], max_steps: int) -> None:
    print(f"\n2. pose latency, step end on the server -> arrival at a viewer ({world}, max speed, {max_steps} steps)")
    for n in viewers:
        run_id = queued_run(url, world, max_steps=max_steps)
        latencies, counts, deflated = asyncio.run(
            watch_many(f"{url.replace('http', 'ws')}/ws/runs/{run_id}?timing=1", n)
        )
        run = wait_ended(url, run_id)
        ms = [1e3 * v for v in latencies]
        print(
            f"   {n:3d} viewer(s): p50 {percentile(ms, 50):6.2f} ms, p99 {percentile(ms, 99):6.2f} ms, "
            f"max {max(ms):6.1f} ms over {len(ms)} step messages "
            f"({run['progress']['step']} steps in {run['wall_time_s']:.1f} s, min {min(counts)} steps per viewer; "
            f"permessage-deflate: {deflated} of {n})"
        )


# -- 3. slowdown -----------------------------------------------------------------------------------
async def drain(url: str, path: str) -> tuple[int, bool]:
    """A viewer that costs its own machine next to nothing: the handshake, then read and discard bytes.

    It offers permessage-deflate as a browser does, so that the service compresses for it whenever it
    has ``ws_compression`` on; the frames are counted, never inflated. Returns the bytes received after
    the handshake and whether the service accepted the offer.

    (Real viewers are browsers on other machines; parsing 50 streams here would compete with the
    service for this machine's cores and be counted as the service's slowdown.)"""
    host, port = url.removeprefix("http://").split(":")
    reader, writer = await asyncio.open_connection(host, int(port))
    writer.write(
        f"GET {path} HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
        "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
        "Sec-WebSocket-Extensions: permessage-deflate; client_max_window_bits\r\n\r\n".encode()
    )
    head = (await reader.readuntil(b"\r\n\r\n")).decode("latin-1").lower()
    assert head.startswith("http/1.1 101"), head.splitlines()[0]
    deflated = any(
        line.startswith("sec-websocket-extensions:") and "permessage-deflate" in line for line in head.splitlines()
    )
    received = 0
    while chunk := await reader.read(1 << 16):
        received += len(chunk)
    writer.close()
    return received, deflated


@dataclass
class Timed:
    """One run: its wall time, CPU times while it ran [s], what its viewers received."""

    wall_s: float
    tree_cpu_s: float  # the service with its engine processes
    service_cpu_s: float  # the service process alone (its event loop and threads)
    loop_cpu_s: float  # the event loop's thread
    loop_switches: int  # the event loop's thread's context switches
    received: int  # bytes, all viewers
    deflated: int  # viewers that got permessage-deflate


async def timed_run(url: str, world: str, viewers: int, max_steps: int) -> Timed:
    run_id = await asyncio.to_thread(queued_run, url, world, max_steps=max_steps)
    viewing = [asyncio.create_task(drain(url, f"/ws/runs/{run_id}")) for _ in range(viewers)]
    await asyncio.sleep(0.8)  # the viewers connect while the run waits its turn (about 2 s)
    pid = SERVICE_PID[0]
    tree0, cpu0, loop0 = tree_cpu_seconds(pid), cpu_seconds(pid), cpu_seconds(pid, main_thread_only=True)
    switches0 = context_switches(pid)
    drained = await asyncio.gather(*viewing)
    run = await asyncio.to_thread(wait_ended, url, run_id)
    await asyncio.to_thread(wait_engines_reaped, pid)  # so that its engine's CPU time has been added up
    return Timed(
        float(run["wall_time_s"]),
        tree_cpu_seconds(pid) - tree0,
        cpu_seconds(pid) - cpu0,
        cpu_seconds(pid, main_thread_only=True) - loop0,
        context_switches(pid) - switches0,
        sum(b for b, _ in drained),
        sum(d for _, d in drained),
    )


def bench_slowdown(url: str, world: str, viewers: int, repeats: int, max_steps: int) -> None:
    print(f"\n3. max-speed run wall time, {viewers} viewers vs none ({world}, {max_steps} steps, {repeats} pairs)")
    alone: list[Timed] = []
    watched: list[Timed] = []
    for _ in range(repeats):  # alternate, so that drift in machine load hits both alike
        alone.append(asyncio.run(timed_run(url, world, 0, max_steps)))
        watched.append(asyncio.run(timed_run(url, world, viewers, max_steps)))

    def median(runs: list[Timed], key: str) -> float:
        return statistics.median(getattr(t, key) for t in runs)

    a, w = median(alone, "wall_s"), median(watched, "wall_s")
    best_a, best_w = min(t.wall_s for t in alone), min(t.wall_s for t in watched)
    deflated = [t.deflated for t in watched]
    print(
        f"   viewers offer permessage-deflate; the service accepted it for {min(deflated)}-{max(deflated)} of "
        f"{viewers}; {median(watched, 'received') / viewers / 1e3:.1f} kB on the wire per viewer and run (median)"
    )
    print(f"   no viewers: median {a:.2f} s, best {best_a:.2f} s {sorted(round(t.wall_s, 2) for t in alone)}")
    print(f"   {viewers} viewers: median {w:.2f} s, best {best_w:.2f} s {sorted(round(t.wall_s, 2) for t in watched)}")
    # Other work on the machine only ever adds time: the best of several runs is the steadiest figure.
    print(f"   slowdown: {100 * (best_w / best_a - 1):+.1f} % (best), {100 * (w / a - 1):+.1f} % (median)")
    for label, key in (
        ("service CPU time, with its engine processes", "tree_cpu_s"),
        ("the service process alone (event loop and threads)", "service_cpu_s"),
    ):
        ca, cw = median(alone, key), median(watched, key)
        print(f"   {label}: {ca:.2f} s alone, {cw:.2f} s with {viewers} viewers: {100 * (cw / ca - 1):+.1f} %")
    la, lw = median(alone, "loop_cpu_s"), median(watched, "loop_cpu_s")
    # With the engine on a thread of the service, the loop's extra CPU time is time it took from the run
    # (one interpreter lock); with the engine in a child process it competes only for the machine's cores.
    print(
        f"   event loop CPU time: {la:.2f} s alone, {lw:.2f} s with {viewers} viewers: the viewers cost it "
        f"{lw - la:.2f} s, {100 * (lw - la) / a:.1f} % of the run's wall time"
    )
    # A loop that contends with the engine for the interpreter lock switches many times more often.
    for label, runs in (("alone", alone), (f"with {viewers} viewers", watched)):
        print(f"   event loop context switches {label}: {sorted(t.loop_switches for t in runs)}")


def bench_start(url: str, world: str, runs: int) -> None:
    """From the request to the run's first step being under way: created_at to started_at, as the service
    records them (validation, the run's folder, the engine process if any, opening the simulator)."""
    print(f"\n4. start latency, {runs} one-step runs of {world} one after another (created -> started)")
    took: list[float] = []
    for _ in range(runs):
        run = wait_ended(url, start_run(url, world, max_steps=1))
        took.append(1e3 * (iso_seconds(run["started_at"]) - iso_seconds(run["created_at"])))
    print(
        f"   first {took[0]:.0f} ms; the others median {statistics.median(took[1:]):.0f} ms, "
        f"best {min(took[1:]):.0f} ms, worst {max(took[1:]):.0f} ms"
    )


def iso_seconds(text: str) -> float:
    return datetime.fromisoformat(text).timestamp()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=("bytes", "latency", "slowdown", "start"), default=None)
    parser.add_argument("--world", default="room1")
    parser.add_argument("--viewers", type=int, default=50)
    parser.add_argument("--steps", type=int, default=400, help="steps per latency / slowdown run")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--ws-compression",
        choices=("true", "false"),
        default=None,
        help="the service's ws_compression for latency and slowdown (default: the service's default)",
    )
    parser.add_argument(
        "--sim-engine",
        choices=("process", "thread"),
        default=None,
        help="where the service runs a simulated run's engine (default: the service's default, a child process)",
    )
    args = parser.parse_args(argv)
    print(f"cpus: {os.cpu_count()}, load average: {os.getloadavg()[0]:.2f}")
    if args.only in (None, "bytes"):
        # Every step to the viewer (no rate cap), so that nothing is saved by merging; deflate offered.
        settings = {"ws_max_rate_hz": "10000", "ws_compression": "true"}
        print("\n   every step sent (rate cap off): what a viewer of a real-time run gets")
        with tempfile.TemporaryDirectory() as tmp, service(Path(tmp), **settings) as url:
            bench_bytes(url, args.world, [0.2, 0.1])
        # The default rate cap: at most ws_max_rate_hz messages a second per viewer, so the steps of
        # a max-speed run that come faster are merged, as a dashboard needs no more. Plain text is what
        # every viewer gets at the default settings; the deflate lines are what a browser gets with
        # ws_compression on.
        rate = ServerSettings.model_fields["ws_max_rate_hz"].default
        print(
            f"\n   DEFAULT RATE CAP (at most {rate:g} messages a second per viewer), "
            "max-speed run; plain text is the "
            "default,\n   permessage-deflate what a browser gets with ws_compression on"
        )
        with tempfile.TemporaryDirectory() as tmp, service(Path(tmp), ws_compression="true") as url:
            bench_bytes(url, args.world, [0.2, 0.1])
    overrides = {} if args.ws_compression is None else {"ws_compression": args.ws_compression}
    if args.sim_engine is not None:
        overrides["sim_engine"] = args.sim_engine
    if args.only in (None, "latency", "slowdown", "start"):
        which = ", ".join(f"{k}={v}" for k, v in overrides.items()) or "default settings"
        print(f"\n   latency, slowdown and start: service with {which}; viewers offer permessage-deflate")
    with tempfile.TemporaryDirectory() as tmp, service(Path(tmp), **overrides) as url:
        if args.only in (None, "start"):
            bench_start(url, args.world, 12)  # first: the first run may wait for the service's warm-up
        if args.only in (None, "latency"):
            bench_latency(url, args.world, [1, args.viewers], args.steps)
        if args.only in (None, "slowdown"):
            bench_slowdown(url, args.world, args.viewers, args.repeats, args.steps)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
