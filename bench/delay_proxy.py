"""A TCP proxy that makes localhost look like a network link: every chunk is delivered a fixed delay after it
arrived (each way, so a round trip costs twice that) and each direction of the link, all connections together, is
held to a byte rate.
For `make bench-map-store`'s drive, in front of nginx; asyncio, one thread, no third-party code.

    proxy = DelayProxy(upstream_port, one_way_delay_s=0.025, rate_bytes_s=10e6)
    proxy.start()  # serves on proxy.port until proxy.stop()
"""

from __future__ import annotations

import asyncio
import socket
import threading
import time


class DelayProxy:
    def __init__(self, upstream_port: int, one_way_delay_s: float, rate_bytes_s: float) -> None:
        self.upstream_port = upstream_port
        self.delay = one_way_delay_s
        self.rate = rate_bytes_s
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="delay_proxy", daemon=True)
        self._server: asyncio.base_events.Server | None = None
        self._link_free_at = {"up": 0.0, "down": 0.0}  # when each direction has sent what it was given (monotonic)

    def start(self) -> None:
        self._thread.start()
        future = asyncio.run_coroutine_threadsafe(asyncio.start_server(self._serve, "127.0.0.1", self.port), self._loop)
        self._server = future.result(timeout=5)

    def stop(self) -> None:
        if self._server is not None:
            self._loop.call_soon_threadsafe(self._server.close)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)

    async def _serve(self, client_reader: asyncio.StreamReader, client_writer: asyncio.StreamWriter) -> None:
        try:
            upstream_reader, upstream_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)
        except OSError:
            client_writer.close()  # the server is down: the client sees the connection closed
            return
        requests = self._pipe(client_reader, upstream_writer, "up")
        answers = self._pipe(upstream_reader, client_writer, "down")
        await asyncio.gather(requests, answers, return_exceptions=True)

    async def _pipe(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, direction: str) -> None:
        """Copies reader to writer: each chunk leaves `delay` after it came, and no sooner than the rate of the
        link's `direction` allows (shared by every connection: one event loop thread, so no lock)."""
        queue: asyncio.Queue = asyncio.Queue()

        async def deliver() -> None:
            while True:
                arrived, chunk = await queue.get()
                if chunk is None:
                    break
                free_at = max(self._link_free_at[direction], arrived) + len(chunk) / self.rate
                self._link_free_at[direction] = free_at
                wait = max(free_at, arrived + self.delay) - time.monotonic()
                if wait > 0:
                    await asyncio.sleep(wait)
                writer.write(chunk)
                await writer.drain()

        sender = asyncio.ensure_future(deliver())
        try:
            while chunk := await reader.read(65536):
                queue.put_nowait((time.monotonic(), chunk))
        finally:
            queue.put_nowait((0.0, None))
            await asyncio.gather(sender, return_exceptions=True)
            writer.close()
