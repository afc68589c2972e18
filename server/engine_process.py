"""A run's body in a child process: start it, carry its messages to the event loop, pass it orders, see it end.

Why: a simulated run's step engine is pure Python and numpy at full speed. On a thread of the service it
holds the interpreter lock that the event loop needs to serve the run's viewers, and now and then the two
fight over it (the loop woke 25 times as often, and the run took up to a quarter longer). In a child
process each has an interpreter of its own.

How:
- Children come from a forkserver (``multiprocessing``'s "forkserver" context): the service has threads,
  so a plain fork is unsafe, and the forkserver has already imported numpy, the engine and the simulator
  (``PRELOAD``), so that starting a run costs a fork rather than a second of imports. ``warm_up`` starts it
  with the service.
- Messages (``server.run_body.Post``) go child -> parent over a pipe, each a length-prefixed pickle. The
  child never blocks on it: what the pipe cannot take yet waits in a buffer that the next message or a
  flusher thread writes when there is room, so a parent that falls behind gets many steps per read. The
  parent reads the pipe on the event loop (``loop.add_reader``) and hands each message to ``deliver``.
- Orders (``("stop", reason)``, ``("speed", value)``) go parent -> child over a second pipe, read by a
  thread of the child. When that pipe closes without a word the service has gone (``kill -9``): the child
  exits at once, touching nothing, so that the run stays recoverable as ``interrupted``.
- The child ignores SIGINT and SIGTERM (a terminal's Ctrl-C and systemd reach the whole process group):
  the service decides when its runs stop.
- The parent sees the end as end-of-file on the message pipe, then reaps the child; ``on_end`` learns
  whether it ended by itself (a terminal status came through) or how it died.

Process calls (start, join) go through one thread of their own (``_launcher``): ``Process.start`` polls
every other child, and two threads polling one child's sentinel could each take half of its exit code.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import os
import pickle
import select
import signal
import struct
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import cache
from multiprocessing.connection import Connection
from typing import Any

log = logging.getLogger("sonarslam.server")

# Imported once by the forkserver; every child starts from them. "__main__" spares the child from importing
# the service's entry script again (as multiprocessing otherwise does when the service runs from a script);
# like any multiprocessing program, a script that starts the service keeps it under `if __name__ == "__main__"`.
PRELOAD = ["__main__", "server.run_body"]
HEADER = struct.Struct("!I")  # a message's length [bytes]
READ_SIZE = 1 << 18  # what the parent reads from the pipe at once [bytes]
JOIN_TIMEOUT_S = 10.0  # how long a child that closed its pipe may take to exit before it is killed
ORPHANED = 3  # a child's exit status when the service has gone

Message = tuple[Any, ...]
Deliver = Callable[[Message], None]


def _context() -> multiprocessing.context.ForkServerContext:
    ctx = multiprocessing.get_context("forkserver")
    assert isinstance(ctx, multiprocessing.context.ForkServerContext)
    ctx.set_forkserver_preload(PRELOAD)
    return ctx


@cache
def _launcher() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=1, thread_name_prefix="engine-launcher")


def warm_up() -> None:
    """Start the forkserver and its imports now, so that the first run starts as fast as the others."""
    _context()
    from multiprocessing import forkserver

    _launcher().submit(forkserver.ensure_running)


# -- the child's side ---------------------------------------------------------------------------------
class FrameWriter:
    """The child's end of the message pipe: length-prefixed pickles, written without ever blocking the caller."""

    def __init__(self, conn: Connection) -> None:
        self.conn = conn
        self.fd = conn.fileno()
        os.set_blocking(self.fd, False)
        self._pending = bytearray()
        self._lock = threading.Lock()
        self._backlog = threading.Event()  # set while the flusher owns the pending bytes
        self._flusher: threading.Thread | None = None
        self._closed = False

    def send(self, message: Message) -> None:
        data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        with self._lock:
            self._pending += HEADER.pack(len(data))
            self._pending += data
            if self._backlog.is_set():
                return  # the flusher writes it after what is already waiting
            self._write()
            if self._pending:
                self._backlog.set()
                if self._flusher is None:
                    self._flusher = threading.Thread(target=self._flush_when_ready, name="messages", daemon=True)
                    self._flusher.start()

    def _write(self) -> None:
        try:
            written = os.write(self.fd, self._pending)
        except BlockingIOError:
            return
        except BrokenPipeError:
            os._exit(ORPHANED)  # the service has gone: so has its run
        del self._pending[:written]

    def _flush_when_ready(self) -> None:
        while True:
            self._backlog.wait()
            with contextlib.suppress(OSError):  # closed meanwhile
                select.select([], [self.fd], [])
            with self._lock:
                if self._closed:
                    return
                self._write()
                if not self._pending:
                    self._backlog.clear()

    def close(self) -> None:
        """Write everything still waiting, then close: the parent reads end-of-file after the last message."""
        with self._lock:
            os.set_blocking(self.fd, True)
            while self._pending:
                self._write()
            self._closed = True
            self.conn.close()


def _listen(orders: Connection, obey: Callable[[Message], None]) -> None:
    while True:
        try:
            message = orders.recv()
        except (EOFError, OSError):
            os._exit(ORPHANED)  # the service has gone without a word (kill -9): end as it did, at once
        try:
            obey(message)
        except Exception:
            log.exception("could not carry out %r", message)


Listen = Callable[[Callable[[Message], None]], None]


def _child_main(target: Callable[..., None], args: tuple[Any, ...], messages: Connection, orders: Connection) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    writer = FrameWriter(messages)

    def listen(obey: Callable[[Message], None]) -> None:
        threading.Thread(target=_listen, args=(orders, obey), name="orders", daemon=True).start()

    try:
        target(*args, post=writer.send, listen=listen)
    finally:
        writer.close()


# -- the parent's side --------------------------------------------------------------------------------
class FrameReader:
    """The parent's end of the message pipe: bytes as they come in, whole messages out."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, chunk: bytes) -> list[Message]:
        buf = self._buffer
        buf += chunk
        at, messages = 0, []
        while len(buf) - at >= HEADER.size:
            (size,) = HEADER.unpack_from(buf, at)
            if len(buf) - at - HEADER.size < size:
                break  # the rest of it is on its way
            at += HEADER.size
            messages.append(pickle.loads(buf[at : at + size]))
            at += size
        del buf[:at]
        return messages


def describe_exit(exitcode: int | None) -> str:
    if exitcode is None:
        return "did not exit"
    if exitcode < 0:
        with contextlib.suppress(ValueError):
            return f"was killed by {signal.Signals(-exitcode).name}"
        return f"was killed by signal {-exitcode}"
    return f"exited with status {exitcode}"


class EngineProcess:
    """``target(*args, post=..., listen=...)`` in a child process, as the event loop sees it.

    ``deliver`` gets every message the child posts, on the loop, in order. ``on_end(reason)`` is called
    once, on the loop, after the last: ``reason`` is None when the child ended by itself (``ended_by``
    says so for a message), else why it did not ("was killed by SIGKILL", "could not start: ...")."""

    def __init__(
        self,
        name: str,
        target: Callable[..., None],
        args: tuple[Any, ...],
        deliver: Deliver,
        ended_by: Callable[[Message], bool],
        on_end: Callable[[str | None], None],
    ) -> None:
        ctx = _context()
        self._messages, self._child_messages = ctx.Pipe(duplex=False)
        self._child_orders, self._orders = ctx.Pipe(duplex=False)
        self.process = ctx.Process(
            target=_child_main, args=(target, args, self._child_messages, self._child_orders), name=name, daemon=True
        )
        self.deliver = deliver
        self.ended_by = ended_by
        self.on_end = on_end
        self.ended = False  # a message said the child has finished its work
        self._frames = FrameReader()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._launch: asyncio.Future[None] | None = None
        self._end: asyncio.Task[None] | None = None

    @property
    def pid(self) -> int | None:
        return self.process.pid

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        fd = self._messages.fileno()
        os.set_blocking(fd, False)
        loop.add_reader(fd, self._readable)
        self._launch = loop.run_in_executor(_launcher(), self._start_child)

    def _start_child(self) -> None:
        t0 = time.perf_counter()
        try:
            self.process.start()
        finally:
            # The child has its own copies now: the parent's would keep the message pipe from ever ending.
            self._child_messages.close()
            self._child_orders.close()
        took_ms = 1e3 * (time.perf_counter() - t0)
        log.debug("%s: child %s started in %.1f ms", self.process.name, self.process.pid, took_ms)

    def order(self, *message: Any) -> None:
        """Pass an order to the child (it may not have started yet: the pipe keeps it)."""
        with contextlib.suppress(OSError):  # the child has gone: its end is on its way
            self._orders.send(message)

    def _readable(self) -> None:
        try:
            chunk = os.read(self._messages.fileno(), READ_SIZE)
        except BlockingIOError:
            return
        except OSError:
            chunk = b""
        if not chunk:
            assert self._loop is not None
            self._loop.remove_reader(self._messages.fileno())
            self._messages.close()
            self._end = self._loop.create_task(self._ended())
            return
        for message in self._frames.feed(chunk):
            self.ended = self.ended or self.ended_by(message)
            self.deliver(message)

    async def _ended(self) -> None:
        """The message pipe has ended: reap the child and say how it ended."""
        assert self._loop is not None and self._launch is not None
        reason: str | None = None
        try:
            await self._launch
        except Exception as exc:
            reason = f"could not start: {type(exc).__name__}: {exc}"
        else:
            exitcode = await self._loop.run_in_executor(_launcher(), self._reap)
            if not self.ended:
                reason = describe_exit(exitcode)
        self._orders.close()
        self.on_end(reason)

    def _reap(self) -> int | None:
        self.process.join(JOIN_TIMEOUT_S)
        if self.process.exitcode is None:
            log.warning("%s: the child closed its pipe but did not exit; killing it", self.process.name)
            self.process.kill()
            self.process.join(JOIN_TIMEOUT_S)
        return self.process.exitcode

    def abandon(self) -> None:
        """The service is leaving without waiting for this child: closing its orders tells it to go too."""
        self._orders.close()
