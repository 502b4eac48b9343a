"""bench/delay_proxy.py against a tiny static server (http.server in a thread), by the closed form of its request
rate: N requests, one at a time or many at once, over kept-alive connections or a connection each, take
(N - 1) / rate plus one round trip (2 x the one-way delay), and one request alone takes the round trip."""

from __future__ import annotations

import functools
import http.client
import http.server
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
from delay_proxy import DelayProxy  # noqa: E402

BODY = b"x" * 8192  # about an urban tile
SLACK_S = 0.25  # scheduling on a shared 2-core machine


class KeepAliveHandler(http.server.SimpleHTTPRequestHandler):
    protocol_version = "HTTP/1.1"  # keeps the connection open between requests, as nginx does
    disable_nagle_algorithm = True  # as nginx's tcp_nodelay: else a kept-alive body waits for the header's ACK

    def log_message(self, *args) -> None:
        pass


class ClosingHandler(KeepAliveHandler):
    protocol_version = "HTTP/1.0"  # closes after every answer, as python3 -m http.server does


class Server(http.server.ThreadingHTTPServer):
    request_queue_size = 64  # its listen() backlog: 5 would drop a burst of connections (a 1 s SYN retry)


@pytest.fixture(params=[KeepAliveHandler, ClosingHandler], ids=["keep_alive", "connection_per_request"])
def server(request, tmp_path):
    (tmp_path / "tile.pcd").write_bytes(BODY)
    handler = functools.partial(request.param, directory=str(tmp_path))
    httpd = Server(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield httpd.server_address[1], request.param is KeepAliveHandler
    httpd.shutdown()
    httpd.server_close()


@pytest.fixture
def proxy_factory():
    proxies = []

    def make(upstream: int, **kwargs) -> DelayProxy:
        proxy = DelayProxy(upstream, **kwargs)
        proxy.start()
        proxies.append(proxy)
        return proxy

    yield make
    for p in proxies:
        p.stop()


def fetch(port: int, count: int, keep_alive: bool) -> None:
    """``count`` GETs of the tile, over one connection when the server keeps it alive, else a connection each."""
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    for _ in range(count):
        conn.request("GET", "/tile.pcd")
        response = conn.getresponse()
        assert response.status == 200 and response.read() == BODY
        if not keep_alive:
            conn.close()
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    conn.close()


def timed(port: int, clients: int, per_client: int, keep_alive: bool) -> float:
    start = time.monotonic()
    with ThreadPoolExecutor(clients) as pool:
        for f in [pool.submit(fetch, port, per_client, keep_alive) for _ in range(clients)]:
            f.result()
    return time.monotonic() - start


@pytest.mark.parametrize("clients", [1, 8])
def test_n_requests_take_n_over_the_rate(server, proxy_factory, clients):
    port, keep_alive = server
    rate, delay, n = 40.0, 0.01, 32
    proxy = proxy_factory(port, one_way_delay_s=delay, rate_requests_s=rate)
    elapsed = timed(proxy.port, clients, n // clients, keep_alive)
    expected = (n - 1) / rate + 2 * delay
    assert proxy.requests == n
    assert expected - 0.02 <= elapsed <= expected + SLACK_S, (elapsed, expected)


def test_without_the_request_rate_many_at_once_pass_quickly(server, proxy_factory):
    port, keep_alive = server
    proxy = proxy_factory(port, one_way_delay_s=0.01)
    elapsed = timed(proxy.port, 8, 4, keep_alive)
    assert elapsed < 31 / 40.0  # what the same requests take at 40 a second
    assert proxy.requests == 32


def test_one_request_takes_a_round_trip(server, proxy_factory):
    port, keep_alive = server
    delay = 0.1
    proxy = proxy_factory(port, one_way_delay_s=delay, rate_requests_s=1000.0)
    elapsed = timed(proxy.port, 1, 1, keep_alive)
    assert 2 * delay <= elapsed <= 2 * delay + SLACK_S


def test_the_byte_rate_still_holds(server, proxy_factory):
    port, keep_alive = server
    rate_bytes = 200e3  # 10 tiles of 8 KiB: about 0.41 s down
    proxy = proxy_factory(port, one_way_delay_s=0.0, rate_bytes_s=rate_bytes, rate_requests_s=1000.0)
    elapsed = timed(proxy.port, 2, 5, keep_alive)
    assert 10 * len(BODY) / rate_bytes <= elapsed <= 10 * len(BODY) / rate_bytes + SLACK_S
