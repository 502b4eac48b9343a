"""A TCP proxy that makes localhost look like a network link: every chunk is delivered a fixed delay after it
arrived (each way, so a round trip costs twice that), each direction of the link, all connections together, may be
held to a byte rate, and the requests, all connections together, to a request rate (a server that answers at most
so many tiles a second).
For `make bench-map-store`'s drives, in front of nginx; asyncio, one thread, no third-party code.

    proxy = DelayProxy(upstream_port, one_way_delay_s=0.025, rate_bytes_s=10e6)
    proxy = DelayProxy(upstream_port, one_way_delay_s=0.05, rate_requests_s=50.0)  # 100 ms a request, 50 a second
    proxy.start()  # serves on proxy.port until proxy.stop()

As a program (the gtests' slow store), until SIGTERM or SIGINT:

    python3 bench/delay_proxy.py UPSTREAM_PORT --port PORT [--delay S] [--requests-per-second R] [--bytes-per-second B]

The request rate counts HTTP request heads (each ends in an empty line) in what the clients send, so it holds for
requests without a body (GET, HEAD), over kept-alive connections as over a connection per request. Request k is
passed on to the server at its slot, s_k = max(arrival + one-way delay, s_(k-1) + 1 / rate), and its answer comes
back a one-way delay later: answers start at most `rate` a second, and no sooner than a round trip after the request.
"""

from __future__ import annotations

import argparse
import asyncio
import signal
import socket
import sys
import threading
import time

HEAD_END = b"\r\n\r\n"  # the empty line after an HTTP request's header fields


class DelayProxy:
    def __init__(
        self,
        upstream_port: int,
        one_way_delay_s: float,
        rate_bytes_s: float | None = None,
        rate_requests_s: float | None = None,
        port: int = 0,
    ) -> None:
        """``port``: where it listens on 127.0.0.1 (0: a free port, in ``self.port``)."""
        self.upstream_port = upstream_port
        self.delay = one_way_delay_s
        self.rate = rate_bytes_s  # None: no byte limit
        self.request_rate = rate_requests_s  # None: no request limit
        self.requests = 0  # request heads seen (all connections)
        self.port = port
        if not port:
            with socket.socket() as s:
                s.bind(("127.0.0.1", 0))
                self.port = s.getsockname()[1]
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="delay_proxy", daemon=True)
        self._server: asyncio.base_events.Server | None = None
        self._link_free_at = {"up": 0.0, "down": 0.0}  # when each direction has sent what it was given (monotonic)
        self._last_slot = -float("inf")  # when the last request was passed on (monotonic)

    def start(self) -> None:
        self._thread.start()
        future = asyncio.run_coroutine_threadsafe(asyncio.start_server(self._serve, "127.0.0.1", self.port), self._loop)
        self._server = future.result(timeout=5)

    def stop(self) -> None:
        """Closes the listening socket and every connection, and ends the thread."""
        if not self._thread.is_alive():
            return

        async def shut_down() -> None:
            if self._server is not None:
                self._server.close()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

        asyncio.run_coroutine_threadsafe(shut_down(), self._loop).result(timeout=5)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=5)
        self._loop.close()

    async def _serve(self, client_reader: asyncio.StreamReader, client_writer: asyncio.StreamWriter) -> None:
        try:
            upstream_reader, upstream_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)
        except OSError:
            client_writer.close()  # the server is down: the client sees the connection closed
            return
        requests = self._pipe(client_reader, upstream_writer, "up")
        answers = self._pipe(upstream_reader, client_writer, "down")
        await asyncio.gather(requests, answers, return_exceptions=True)

    def _request_slot(self, arrived: float, heads: int) -> float:
        """When the last of ``heads`` requests that arrived at ``arrived`` may go on to the server (-inf: now)."""
        if self.request_rate is None or heads == 0:
            return -float("inf")
        for _ in range(heads):
            self._last_slot = max(arrived + self.delay, self._last_slot + 1.0 / self.request_rate)
        return self._last_slot

    async def _pipe(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, direction: str) -> None:
        """Copies reader to writer: each chunk leaves `delay` after it came, no sooner than the byte rate of the
        link's `direction` allows, and (up) not before the slot of the last request it completes (the link and the
        slots are shared by every connection: one event loop thread, so no lock)."""
        queue: asyncio.Queue = asyncio.Queue()

        async def deliver() -> None:
            while True:
                arrived, not_before, chunk = await queue.get()
                if chunk is None:
                    break
                free_at = self._link_free_at[direction]
                if self.rate is not None:
                    free_at = max(free_at, arrived) + len(chunk) / self.rate
                    self._link_free_at[direction] = free_at
                wait = max(free_at, arrived + self.delay, not_before) - time.monotonic()
                if wait > 0:
                    await asyncio.sleep(wait)
                writer.write(chunk)
                await writer.drain()

        sender = asyncio.ensure_future(deliver())
        tail = b""  # the end of the previous chunk: a head's empty line may straddle two chunks
        try:
            while chunk := await reader.read(65536):
                arrived = time.monotonic()
                heads = 0
                if direction == "up":
                    heads = (tail + chunk).count(HEAD_END)
                    tail = (tail + chunk)[-(len(HEAD_END) - 1) :]
                    self.requests += heads
                queue.put_nowait((arrived, self._request_slot(arrived, heads), chunk))
        finally:
            queue.put_nowait((0.0, 0.0, None))
            await asyncio.gather(sender, return_exceptions=True)
            writer.close()


def main() -> int:
    parser = argparse.ArgumentParser(description="A delaying, rate-limiting TCP proxy to 127.0.0.1:UPSTREAM_PORT.")
    parser.add_argument("upstream_port", type=int)
    parser.add_argument("--port", type=int, required=True, help="where it listens on 127.0.0.1")
    parser.add_argument("--delay", type=float, default=0.0, help="one-way delay [s] (0)")
    parser.add_argument("--requests-per-second", type=float, help="at most this many requests a second (no limit)")
    parser.add_argument("--bytes-per-second", type=float, help="each direction's byte rate (no limit)")
    args = parser.parse_args()
    proxy = DelayProxy(args.upstream_port, args.delay, args.bytes_per_second, args.requests_per_second, args.port)
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    proxy.start()
    stop.wait()
    proxy.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
