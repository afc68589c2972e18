"""``sonarslam serve`` as its own process on an ephemeral loopback port, for tests that need the real
path from settings (environment variables) to uvicorn, or a real process to kill."""

from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx

URL_LINE = re.compile(r"(http://127\.0\.0\.1:\d+)/")


@contextmanager
def serve_process(data_dir: Path, **settings: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """Start the service with default settings plus ``settings`` (as ``SONARSLAM_*`` variables);
    yields the process and its base URL once it answers, and stops it afterwards."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("SONARSLAM_")}
    env |= {"SONARSLAM_LOG_LEVEL": "warning"} | {f"SONARSLAM_{k.upper()}": v for k, v in settings.items()}
    proc = subprocess.Popen(
        [sys.executable, "-m", "robot", "serve", "--port", "0", "--data-dir", str(data_dir)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in proc.stdout or ()], daemon=True).start()
    try:
        deadline = time.monotonic() + 30
        url = None
        while url is None:
            match = URL_LINE.search(lines.get(timeout=max(0.1, deadline - time.monotonic())))
            url = match.group(1) if match else None
        with httpx.Client(base_url=url, timeout=10) as client:
            while True:  # the URL is printed just before uvicorn takes over the socket
                try:
                    if client.get("/api/health").status_code == 200:
                        break
                except httpx.TransportError:
                    assert time.monotonic() < deadline, "the service did not come up"
                    time.sleep(0.05)
        yield proc, url
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)
