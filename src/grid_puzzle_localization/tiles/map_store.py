"""A tiled map served over HTTP(S): the Python twin of the C++ MapStore (include/grid_puzzle_localization/
map_store/map_store.hpp, docs/map_store.md), with the same checks, revision and disk cache layout. The server holds
what `gpm tile` writes (index.json + <cx>_<cy>.pcd) under a URL prefix.

HTTP is urllib3 (Debian's python3-urllib3, also in Ubuntu 20.04): one connection pool kept alive between fetches,
connect and whole-request timeouts, certificate verification against the system CA store. Tiles are fetched on
``max_connections`` threads (CLOSING_SERVER_CONNECTIONS to a server that closes every connection); each body is
refused as soon as it passes the size the index gives, then checked (size, SHA-256) before it is stored by temporary
file and rename. Nothing here imports rospy or numpy.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import os
import re
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiling.index import FORMAT, INDEX_FILE, VERSION

_TEMP_PREFIX = ".tmp-"
_SHA256_HEX = re.compile(r"[0-9a-f]{64}")
_counter = itertools.count()


def is_map_store_url(location: str | os.PathLike) -> bool:
    """True for "http://..." and "https://...": where a tile directory is accepted, such a string names a map store."""
    return isinstance(location, str) and location.startswith(("http://", "https://"))


def unsafe_tile_name(name: str) -> str:
    """ "" when ``name`` is safe to append to the URL and the cache directory, else why not (the C++ rule)."""
    if not name:
        return "an empty name"
    if len(name.encode()) > 255:
        return "longer than 255 bytes"
    if ".." in name:
        return "it holds '..'"
    if name.startswith("."):
        return "it starts with '.'"
    for c in name:
        if c in "/\\":
            return "it holds a path separator"
        if ord(c) < 0x20 or ord(c) == 0x7F:
            return "it holds a control character"
        if c in "%?#":
            return "it holds '%', '?' or '#'"
    return ""


def checked_url(url: str) -> str:
    """``url`` without a trailing '/'; UserError naming it when it is not a usable map URL."""

    def bad(why: str) -> UserError:
        return UserError(f"map store URL '{url}': {why}")

    if not is_map_store_url(url):
        raise bad("only http:// and https:// are supported")
    if any(ord(c) <= 0x20 or ord(c) == 0x7F for c in url):
        raise bad("it holds white space or control characters")
    if "?" in url or "#" in url:
        raise bad("a query or fragment cannot be extended with tile names; give the directory's URL")
    rest = url.split("://", 1)[1]
    authority = rest.split("/", 1)[0]
    if not authority:
        raise bad("no host")
    if "@" in authority:
        raise bad("credentials in the URL would be logged; use map_store/bearer_token_file or basic_auth_file")
    return url.rstrip("/")


@dataclass
class MapStoreConfig:
    """The map store's settings (``map_store/*``); the defaults are the C++ MapStoreConfig's."""

    cache_dir: str = ""  # "" = $XDG_CACHE_HOME (else ~/.cache)/grid_puzzle_localization/map_store
    cache_max_bytes: int = 1 << 30  # tile bytes kept on disk per map URL
    connect_timeout: float = 5.0  # [s]
    transfer_timeout: float = 30.0  # [s] one whole request
    max_retries: int = 3  # further attempts after a failed one
    retry_backoff: float = 0.5  # [s] before the first retry, doubled for each next one
    max_connections: int = 16  # concurrent fetches and kept-alive connections
    max_tile_bytes: int = 256 << 20
    max_index_bytes: int = 1 << 30
    ca_file: str = ""  # "" = the system CA store
    bearer_token_file: str = ""
    bearer_token_env: str = ""
    basic_auth_file: str = ""
    poll_period: float = 5.0  # [s] between polls of index.json (provider)

    def check(self) -> None:
        """UserError naming the first bad field."""
        problems = [
            (self.cache_max_bytes > 0, "cache_max_bytes must be > 0"),
            (self.connect_timeout > 0, "connect_timeout must be > 0 s"),
            (self.transfer_timeout > 0, "transfer_timeout must be > 0 s"),
            (0 <= self.max_retries <= 20, "max_retries must be in [0, 20]"),
            (0 <= self.retry_backoff <= 60, "retry_backoff must be in [0, 60] s"),
            (1 <= self.max_connections <= 64, "max_connections must be in [1, 64]"),
            (self.max_tile_bytes > 0, "max_tile_bytes must be > 0"),
            (self.max_index_bytes > 0, "max_index_bytes must be > 0"),
            (self.poll_period > 0, "poll_period must be > 0 s"),
        ]
        for ok, what in problems:
            if not ok:
                raise UserError(f"map_store/{what}")


@dataclass(frozen=True)
class IndexTile:
    file: str
    bytes: int
    sha256: str  # "" in an index written without checksums


@dataclass
class MapStoreStatus:
    url: str
    reachable: bool = True
    last_error: str = ""
    revision: str = ""
    tiles_fetched: int = 0
    cache_hits: int = 0
    failed_attempts: int = 0
    bytes_fetched: int = 0
    cache_bytes: int = 0
    parallel_requests: int = 0  # requests run at once now: max_connections, or see CLOSING_SERVER_CONNECTIONS


# Requests run at once against a server that closes the connection after every answer (HTTP/1.0 such as
# `python3 -m http.server`, or "Connection: close"): each request opens a connection, and a burst of them overflows
# a small accept queue (Python's socketserver: a backlog of 5), where every dropped connection waits out TCP's 1 s
# SYN retransmission and holds up its whole fetch. Four never overflow a backlog of 5. The twin of
# kClosingServerConnections in map_store.hpp.
CLOSING_SERVER_CONNECTIONS = 4


def keeps_alive(version: int, connection: str) -> bool:
    """True when an answer of HTTP ``version`` (10, 11, ...) with this Connection header leaves its connection open:
    HTTP/1.1 unless "close", HTTP/1.0 only with "keep-alive"."""
    tokens = connection.lower()
    return "keep-alive" in tokens if version == 10 else "close" not in tokens


@dataclass
class FetchedTile:
    id: str
    path: Path | None = None  # the checked copy in the cache
    error: str = ""


def parse_index(text: bytes, what: str) -> tuple[float, dict[str, IndexTile]]:
    """Grid size [m] and the tiles by stem of an index.json's bytes; UserError naming ``what`` when it is not a
    tile index, names a tile unsafely, or has a partial or malformed checksum column."""
    try:
        raw = json.loads(text)
        if not isinstance(raw, dict) or raw.get("format") != FORMAT or raw.get("version") != VERSION:
            raise ValueError(f"not a version {VERSION} {FORMAT} index")
        s = float(raw["grid_size"])
        if not s > 0:
            raise ValueError("no positive grid_size")
        tiles: dict[str, IndexTile] = {}
        with_sum = None
        for entry in raw["tiles"]:
            name, size, digest = entry["file"], entry["bytes"], entry.get("sha256", "")
            if not isinstance(name, str) or not isinstance(size, int) or isinstance(size, bool) or size < 0:
                raise ValueError(f"tile {entry!r:.100} has no file name or size")
            if with_sum is not None and with_sum != bool(digest):
                raise ValueError("some tiles have a sha256 and others have none")
            with_sum = bool(digest)
            if digest and not (isinstance(digest, str) and _SHA256_HEX.fullmatch(digest)):
                raise ValueError(f"a tile's sha256 {digest!r:.80} is not 64 lowercase hex digits")
            why = unsafe_tile_name(name) or ("" if name.endswith(".pcd") and len(name) > 4 else "not a .pcd file")
            if why:
                raise UserError(
                    f"{what}: tile file name '{name[:100]}' is refused ({why}); an index may only name files beside it"
                )
            tiles[name[: -len(".pcd")]] = IndexTile(name, size, digest)
    except UserError:
        raise
    except (ValueError, KeyError, TypeError, RecursionError) as err:
        raise UserError(f"{what}: not a readable tile index ({err}); re-run `gpm tile`") from None
    return s, tiles


def _revision(index_bytes: bytes) -> str:
    return "sha256:" + hashlib.sha256(index_bytes).hexdigest()[:16]


def _write_atomically(path: Path, data: bytes) -> None:
    tmp = path.parent / f"{_TEMP_PREFIX}{os.getpid()}-{next(_counter)}-{path.name}"
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class _DiskCache:
    """Files in one directory, least recently used evicted first past a budget; recency is the files' mtime
    (touched on use), so it survives restarts. One owner (the C++ DiskCache's twin)."""

    def __init__(self, directory: Path, budget: int) -> None:
        self.dir = directory
        self.budget = budget
        directory.mkdir(parents=True, exist_ok=True)
        found = []
        with os.scandir(directory) as entries:
            for e in entries:
                if e.name.startswith(_TEMP_PREFIX):
                    self._drop_temp(e)
                elif e.is_file():
                    st = e.stat()
                    found.append((st.st_mtime_ns, e.name, st.st_size))
        self.entries: dict[str, int] = {name: size for _, name, size in sorted(found)}  # oldest first
        self.bytes = sum(self.entries.values())
        self.pinned: set[str] = set()
        self.evict()

    @staticmethod
    def _drop_temp(entry: os.DirEntry) -> None:
        # A write a crash interrupted; a live process's (another store on this directory) is left alone.
        pid = entry.name[len(_TEMP_PREFIX) :].split("-", 1)[0]
        try:
            os.kill(int(pid), 0)
            alive = int(pid) > 0
        except (ValueError, ProcessLookupError):
            alive = False
        except PermissionError:
            alive = True
        if not alive:
            Path(entry.path).unlink(missing_ok=True)

    def path(self, name: str) -> Path:
        return self.dir / name

    def touch(self, name: str) -> bool:
        if name not in self.entries:
            return False
        self.entries[name] = self.entries.pop(name)
        with contextlib.suppress(OSError):
            os.utime(self.path(name))
        return True

    def store(self, name: str, data: bytes) -> None:
        _write_atomically(self.path(name), data)
        self.bytes += len(data) - self.entries.pop(name, 0)
        self.entries[name] = len(data)

    def remove(self, name: str) -> None:
        self.path(name).unlink(missing_ok=True)
        self.bytes -= self.entries.pop(name, 0)

    def evict(self) -> None:
        for name in list(self.entries):
            if self.bytes <= self.budget:
                break
            if name not in self.pinned:
                self.remove(name)


def default_cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.environ.get("HOME") or "/tmp", ".cache")
    return Path(base) / "grid_puzzle_localization" / "map_store"


class MapStore:
    """See the module docstring. Opening fetches the index; a server that cannot be reached is tolerated when the
    cache holds an index of the URL (the store then starts offline on it). UserError names the URL and what failed."""

    def __init__(self, url: str, config: MapStoreConfig | None = None) -> None:
        import urllib3  # only a store needs it

        self.url = checked_url(url)
        self.config = config or MapStoreConfig()
        self.config.check()
        root = Path(self.config.cache_dir) if self.config.cache_dir else default_cache_root()
        self.dir = root / hashlib.sha256(self.url.encode()).hexdigest()[:16]
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
            _write_atomically(self.dir / "url", (self.url + "\n").encode())
            self._tiles = _DiskCache(self.dir / "tiles", self.config.cache_max_bytes)
        except OSError as err:
            raise UserError(
                f"map store cache directory {self.dir} cannot be used ({err}); set map_store/cache_dir"
            ) from None
        self._urllib3 = urllib3
        headers = self._auth_headers()
        self._pool = urllib3.PoolManager(
            num_pools=2,
            maxsize=self.config.max_connections,
            block=True,
            headers=headers,
            cert_reqs="CERT_REQUIRED",
            ca_certs=self.config.ca_file or None,
            retries=False,
            timeout=urllib3.Timeout(connect=self.config.connect_timeout, total=self.config.transfer_timeout),
        )
        self._lock = threading.Lock()  # status
        self.status = MapStoreStatus(
            self.url, cache_bytes=self._tiles.bytes, parallel_requests=self.config.max_connections
        )
        self.grid_size = 0.0
        self.tiles: dict[str, IndexTile] = {}
        self.etag = ""
        self.revision = ""
        cached = self.dir / INDEX_FILE
        if cached.is_file():
            try:
                self._use(cached.read_bytes(), str(cached))
                self.etag = (self.dir / "index.etag").read_text() if (self.dir / "index.etag").is_file() else ""
            except (UserError, OSError):
                self.tiles = {}
        had_cached = bool(self.tiles)
        try:
            self._poll(strict=True)
        except UserError as err:
            if not had_cached or self.status.reachable:
                raise UserError(
                    f"{err}{'' if had_cached else f'; the cache {self.dir} holds no index of it either'}"
                    "; check the URL and that the server runs"
                ) from None
        if not self.tiles:
            raise UserError(f"map store {self.url}: its index lists no tiles; re-run `gpm tile` on a non-empty map")

    # ---------------------------------------------------------------- HTTP
    def _auth_headers(self) -> dict[str, str]:
        c = self.config

        def first_line(path: str, what: str) -> str:
            try:
                line = Path(path).read_text().splitlines()[0].strip()
            except (OSError, IndexError):
                line = ""
            if not line:
                raise UserError(f"map_store/{what} {path} cannot be read or is empty")
            return line

        if c.bearer_token_file:
            return {"Authorization": "Bearer " + first_line(c.bearer_token_file, "bearer_token_file")}
        if c.bearer_token_env:
            token = os.environ.get(c.bearer_token_env, "")
            if not token:
                raise UserError(f"map_store/bearer_token_env names {c.bearer_token_env}, which is not set or empty")
            return {"Authorization": "Bearer " + token}
        if c.basic_auth_file:
            pair = first_line(c.basic_auth_file, "basic_auth_file")
            if ":" not in pair:
                raise UserError(f"map_store/basic_auth_file {c.basic_auth_file} must hold user:password")
            return self._urllib3.make_headers(basic_auth=pair)
        return {}

    def _get(self, url: str, limit: int, etag: str = "") -> tuple[int, bytes, str, str, bool, bool]:
        """One attempt: (status, body, etag, error, reached, too_large); status 0 without an answer. urllib3's
        timeouts bound each socket read; the whole request is bounded here (a server that drips bytes)."""
        start = time.monotonic()
        try:
            response = self._pool.request(
                "GET",
                url,
                headers={**self._pool.headers, **({"If-None-Match": etag} if etag else {})},
                preload_content=False,
                redirect=False,
            )
        except self._urllib3.exceptions.HTTPError as err:
            return 0, b"", "", str(err), False, False
        self._adapt_to(response.version, response.headers.get("Connection", ""))
        deadline = start + self.config.transfer_timeout
        try:
            length = response.headers.get("Content-Length")
            if length is not None and length.isdigit() and int(length) > limit:
                return response.status, b"", "", f"body larger than {limit} bytes", True, True
            chunks, size = [], 0
            for chunk in response.stream(1 << 16):
                size += len(chunk)
                if size > limit:
                    return response.status, b"", "", f"body larger than {limit} bytes", True, True
                if time.monotonic() > deadline:
                    return (
                        0,
                        b"",
                        "",
                        f"timed out after {self.config.transfer_timeout:g} s (transfer_timeout)",
                        True,
                        False,
                    )
                chunks.append(chunk)
            return response.status, b"".join(chunks), response.headers.get("ETag", ""), "", True, False
        except self._urllib3.exceptions.HTTPError as err:  # cut mid-body, read timeout
            return 0, b"", "", str(err), True, False
        finally:
            response.release_conn()

    def _adapt_to(self, version: int, connection: str) -> None:
        """Fewer requests at once while the server closes its connection after every answer (the last answer
        decides), max_connections while it keeps them alive."""
        closing = min(self.config.max_connections, CLOSING_SERVER_CONNECTIONS)
        with self._lock:
            self.status.parallel_requests = self.config.max_connections if keeps_alive(version, connection) else closing

    @staticmethod
    def _retryable(status: int, too_large: bool) -> bool:
        return not too_large and (status == 0 or status in (408, 429) or status >= 500)

    def _pause(self, attempt: int) -> None:
        time.sleep(self.config.retry_backoff * 2 ** (attempt - 1))

    def _fail(self, error: str, reached: bool) -> None:
        with self._lock:
            self.status.last_error = error
            self.status.reachable = reached
            self.status.failed_attempts += 1

    # ---------------------------------------------------------------- index
    def _use(self, text: bytes, what: str) -> None:
        self.grid_size, self.tiles = parse_index(text, what)
        self.revision = _revision(text)
        self.status.revision = self.revision

    def _poll(self, strict: bool) -> bool:
        url = f"{self.url}/{INDEX_FILE}"
        attempts = 1 + self.config.max_retries if self.status.reachable else 1
        for attempt in range(attempts):
            if attempt:
                self._pause(attempt)
            status, body, etag, error, reached, too_large = self._get(
                url, self.config.max_index_bytes, self.etag if self.tiles else ""
            )
            if not self._retryable(status, too_large):
                break
            self._fail(f"{url}: {error or f'HTTP {status}'}", reached)
        if status == 304:
            self.status.reachable = True
            return False
        if status != 200 or error:
            message = f"cannot fetch {url}: {error or f'HTTP {status}'}"
            self._fail(message, reached)
            if strict:
                raise UserError(message)
            return False
        self.status.reachable = True
        if _revision(body) == self.revision and self.tiles:
            self.etag = etag
            return False
        try:
            self._use(body, url)
        except UserError as err:
            self._fail(str(err), True)
            if strict:
                raise
            return False
        self.etag = etag
        _write_atomically(self.dir / INDEX_FILE, body)
        _write_atomically(self.dir / "index.etag", etag.encode())
        return True

    def poll_index(self) -> bool:
        """True when a new revision of index.json is in use now; False when unchanged or unreachable."""
        return self._poll(strict=False)

    def index_path(self) -> Path:
        """The cached index.json of the revision in use."""
        return self.dir / INDEX_FILE

    # ---------------------------------------------------------------- tiles
    def _cache_name(self, tile: IndexTile) -> str:
        return f"{tile.sha256}.pcd" if tile.sha256 else f"{self.revision[7:]}-{tile.file}"

    @staticmethod
    def _mismatch(tile: IndexTile, data: bytes) -> str:
        if len(data) != tile.bytes:
            short = " (truncated)" if len(data) < tile.bytes else ""
            return f"{len(data)} bytes where the index says {tile.bytes}{short}"
        if tile.sha256 and hashlib.sha256(data).hexdigest() != tile.sha256:
            return "its SHA-256 does not match the index (corrupt, or the map changed on the server)"
        return ""

    def fetch(self, ids: list[str]) -> list[FetchedTile]:
        """The checked cached copies of tiles ``ids`` (stems), fetching the missing ones on max_connections threads.
        Each failure is named in its FetchedTile. The files returned stay in the cache until the next call."""
        self._tiles.pinned.clear()
        out = [FetchedTile(i) for i in ids]
        missing: list[FetchedTile] = []
        for t in out:
            why = unsafe_tile_name(t.id)
            tile = None if why else self.tiles.get(t.id)
            if tile is None:
                t.error = f"tile '{t.id[:100]}' " + (
                    f"is refused ({why})" if why else f"is not in the index of {self.url} (revision {self.revision})"
                )
                continue
            if tile.bytes > self.config.max_tile_bytes:
                t.error = (
                    f"{self.url}/{tile.file}: {tile.bytes} bytes, more than map_store/max_tile_bytes"
                    f" {self.config.max_tile_bytes}; refused"
                )
                continue
            name = self._cache_name(tile)
            if self._tiles.touch(name):
                try:
                    data = self._tiles.path(name).read_bytes()
                except OSError:
                    data = b""
                if not self._mismatch(tile, data):
                    t.path = self._tiles.path(name)
                    self._tiles.pinned.add(name)
                    self.status.cache_hits += 1
                    continue
                self._tiles.remove(name)  # damaged on disk: fetched again
            missing.append(t)
        attempts = 1 + self.config.max_retries if self.status.reachable else 1
        for attempt in range(attempts):
            if not missing:
                break
            if attempt:
                self._pause(attempt)
            tiles = [self.tiles[t.id] for t in missing]
            with ThreadPoolExecutor(self.status.parallel_requests) as pool:
                results = list(
                    pool.map(
                        lambda tile: self._get(f"{self.url}/{tile.file}", min(tile.bytes, self.config.max_tile_bytes)),
                        tiles,
                    )
                )
            again = []
            any_reached = False
            for t, tile, (status, body, _, error, reached, too_large) in zip(missing, tiles, results):
                any_reached = any_reached or reached
                retry = False
                if too_large:
                    why = f"larger than the index's {tile.bytes} bytes; refused before it was stored"
                elif error or status != 200:
                    why = error or f"HTTP {status}"
                    retry = self._retryable(status, too_large)
                else:
                    why = self._mismatch(tile, body)
                    retry = bool(why)
                if not why:
                    name = self._cache_name(tile)
                    self._tiles.store(name, body)
                    self._tiles.pinned.add(name)
                    t.path, t.error = self._tiles.path(name), ""
                    self.status.tiles_fetched += 1
                    self.status.bytes_fetched += len(body)
                    continue
                t.error = f"{self.url}/{tile.file}: {why}"
                self._fail(t.error, reached)
                if retry:
                    again.append(t)
            if any_reached:
                self.status.reachable = True
            missing = again
        self._tiles.evict()
        self.status.cache_bytes = self._tiles.bytes
        return out

    def close(self) -> None:
        self._pool.clear()


__all__ = [
    "FetchedTile",
    "IndexTile",
    "MapStore",
    "MapStoreConfig",
    "MapStoreStatus",
    "checked_url",
    "is_map_store_url",
    "parse_index",
    "unsafe_tile_name",
]
