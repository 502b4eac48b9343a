"""grid_puzzle_map_provider: serves the tiles of the grid puzzle window around the robot.

Subscribes to ``odom`` (nav_msgs/Odometry; then also to ``initialpose``, which seeds the first window
before the localizer has a map) or ``pose`` (PoseWithCovarianceStamped), all in the map frame.
Callbacks only store the latest pose; a worker thread hands it to the window server (provider/window_server.py),
which recomputes the window, finds the tiles that enter and leave it and those likely to enter next, and publishes them
by reference on ``tile_delta`` (TileDelta: tile names and their directory; the localizer reads the files) and
the latched ``~status``. The node holds no point data. When ``publish_map_cloud`` is set it also tells the
map_cloud publisher (map_cloud_publisher.py, a thread of its own) that the window changed; that thread reads
the window's files only while ``map_cloud`` has subscribers.
While the localizer reports itself lost (its NdtStatus on ``localizer_status``) the window grows to hold the
region its search covers (``lost/max_half_side``) and stops following the coasting pose; the first pose after it
tracks again recomputes the window there.
A tile directory rewritten under the running node (a new index revision) is reopened and the whole window
sent again as a reset delta. A tile directory given by URL (a map store: docs/map_store.md) is listed by its
index.json, polled every ``map_store/poll_period``; the localizer fetches the tiles. ``~status`` says whether the
store's server answers, and its last error.
Delta protocol: every broadcast delta increments ``revision`` by one; a new
subscriber first receives a ``reset`` delta of the whole window carrying the current revision; the
service ``~resend`` (std_srvs/Trigger) broadcasts a reset delta so a subscriber that saw a revision gap
can recover.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import rospy
from geometry_msgs.msg import PoseWithCovarianceStamped
from nav_msgs.msg import Odometry
from std_srvs.srv import Trigger, TriggerResponse

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.msg import NdtStatus, ProviderStatus, TileDelta
from grid_puzzle_localization.provider.config import ProviderConfig, load_config
from grid_puzzle_localization.provider.lost_search import SearchRegion, hint_region
from grid_puzzle_localization.provider.tile_references import TileReferences, open_store_directory
from grid_puzzle_localization.provider.window import PoseSample, Window, WindowTracker
from grid_puzzle_localization.provider.window_server import Served, WindowServer
from grid_puzzle_localization.ros.msgs.provider import pose_sample, provider_status, stamped, tile_delta
from grid_puzzle_localization.ros.saved_pose import SavedPoseWriter, read_saved_pose
from grid_puzzle_localization.tiles.directory import open_tile_directory
from grid_puzzle_localization.tiles.map_store import MapStore, MapStoreConfig, is_map_store_url
from grid_puzzle_localization.util.malloc_tuning import limit_arenas, pin_mmap_threshold

WARN_PERIOD = 5.0  # [s] throttle of repeated warnings (off the map, wrong frame)


class ResetOnSubscribe(rospy.SubscribeListener):
    def __init__(self, node: MapProviderNode) -> None:
        super().__init__()
        self.node = node

    def peer_subscribe(self, topic_name, topic_publish, peer_publish):
        self.node.send_reset(peer_publish, increment=False)


class MapProviderNode:
    def __init__(self, config: ProviderConfig, store_config: MapStoreConfig) -> None:
        self.config = config.checked()
        tiles = self.config.tiles
        # A map given by URL must answer now, or have its index in the cache (UserError naming the URL otherwise).
        self.store = MapStore(tiles.dir, store_config) if is_map_store_url(tiles.dir) else None
        if self.store is not None:
            directory = open_store_directory(self.store, tiles.grid_size or None)
        else:
            directory = open_tile_directory(os.path.abspath(tiles.dir), tiles.grid_size or None)
        self.s = directory.grid_size
        if directory.unparsable:
            rospy.logwarn(
                "%s: %d .pcd files are not tiles of side %g m and are ignored: %s",
                tiles.dir,
                len(directory.unparsable),
                self.s,
                ", ".join(directory.unparsable[:10]),
            )
        self.server = WindowServer(
            WindowTracker(self.config.window, self.s),
            TileReferences(directory, self.store),
            self.config.lost.max_half_side,
        )
        self.frame = self.config.map_frame
        # Serialises tile set updates and every publish on tile_delta, so a reset sent to a new subscriber
        # (from rospy's connection thread) or by ~resend is consistent with the delta stream.
        self._lock = threading.Lock()
        self._revision = 0
        self._off_map = False
        self._latest: PoseSample | None = None
        self._search: SearchRegion | None = None  # the lost localizer's latest search region
        self._tracking_again = False  # the localizer tracks again after a loss
        self._posed = False  # a pose came (or was saved): hints and the whole-map start no longer apply
        self._started = time.monotonic()
        self._whole_map_tried = False
        self._pose_ready = threading.Condition()
        self._next_poll = time.monotonic() + store_config.poll_period
        self._store_reachable = True
        self._last_status: ProviderStatus | None = None  # worker only

        self.delta_pub = rospy.Publisher(
            "tile_delta", TileDelta, queue_size=50, subscriber_listener=ResetOnSubscribe(self)
        )
        self.map_cloud = None
        if self.config.publish_map_cloud and self.store is not None:
            rospy.logerr(
                "publish_map_cloud needs a local tile directory, not the URL %s; map_cloud is not published", tiles.dir
            )
        elif self.config.publish_map_cloud:
            # Imported only here: reading and merging tiles needs numpy, which the node otherwise never loads
            # (about 15 MiB of RSS).
            from grid_puzzle_localization.ros.msgs.map_cloud_publisher import MapCloudPublisher

            self.map_cloud = MapCloudPublisher(self._window_paths, self.frame, self.config.map_cloud_period)
        self.status_pub = rospy.Publisher("~status", ProviderStatus, queue_size=10, latch=True)
        rospy.Service("~resend", Trigger, self._on_resend)
        if self.config.pose_source == "odom":
            rospy.Subscriber("odom", Odometry, self._on_odom, queue_size=1)
            # The localizer publishes odom only once it has a map, which in tiles mode comes from here:
            # the start pose (rviz or the experiment runner) seeds the first window.
            rospy.Subscriber("initialpose", PoseWithCovarianceStamped, self._on_initial_pose, queue_size=1)
        else:
            rospy.Subscriber("pose", PoseWithCovarianceStamped, self._on_pose, queue_size=1)
        # The localizer's status: a start it carries while the start's map arrives, and the region it searches when
        # lost.
        if self.config.pose_source == "odom" or self.config.lost.max_half_side > 0.0:
            rospy.Subscriber("localizer_status", NdtStatus, self._on_localizer_status, queue_size=1)
        rospy.Subscriber("initialpose_hint", PoseWithCovarianceStamped, self._on_hint, queue_size=1)
        self._saved_pose = SavedPoseWriter(self.config.save_pose_rate)
        saved = read_saved_pose()
        if saved is not None:
            # A respawn: the window is served at the pose the killed process saved until a pose arrives.
            rospy.loginfo("serves the window around (%.2f, %.2f), the pose saved in ~last_pose", saved[0], saved[1])
            self._latest = PoseSample(saved[0], saved[1], 0.0, saved[5])
            self._posed = True
        self._worker = threading.Thread(target=self._run, name="map_provider_worker", daemon=True)
        self._worker.start()
        rospy.loginfo(
            "grid_puzzle_map_provider: %d tiles of %g m in %s (%s), n=%d k=%d, update distance %g m, listening on %s",
            len(directory),
            self.s,
            tiles.dir,
            directory.source,
            self.server.tracker.config.n,
            self.server.tracker.config.k,
            self.server.tracker.update_distance,
            self.config.pose_source,
        )

    # ------------------------------------------------------------ callbacks (never block)
    def _on_odom(self, msg: Odometry) -> None:
        if self._frame_ok(msg.header.frame_id):
            self._offer(pose_sample(msg.pose.pose, msg.header.stamp, msg.twist.twist))

    def _on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        if self._frame_ok(msg.header.frame_id):
            self._offer(pose_sample(msg.pose.pose, msg.header.stamp))

    def _on_initial_pose(self, msg: PoseWithCovarianceStamped) -> None:
        """A pose given by hand (rviz) ends a search's window: the window goes to that pose."""
        with self._pose_ready:
            self._search = None
            self._tracking_again = True
        self._on_pose(msg)

    def _on_hint(self, msg: PoseWithCovarianceStamped) -> None:
        """A coarse position (GNSS) before any pose: the window holds the localizer's search around it."""
        if msg.header.frame_id not in ("", self.frame):
            rospy.logerr(
                "initialpose_hint is in frame '%s' but map_frame is '%s'; ignored: send the hint in the map frame",
                msg.header.frame_id,
                self.frame,
            )
            return
        p, c = msg.pose.pose.position, msg.pose.covariance
        try:
            region = hint_region(p.x, p.y, c[0], c[7], msg.header.stamp.to_sec())
        except ValueError as err:
            rospy.logerr("initialpose_hint ignored: %s; send x and y in metres in the map frame", err)
            return
        if not self.server.touches_map(region):
            rospy.logerr(
                "initialpose_hint (%.1f, %.1f) m (search radius %.1f m) lies outside the map, which spans"
                " x %.0f..%.0f m, y %.0f..%.0f m; ignored: check the hint's frame and origin",
                p.x,
                p.y,
                region.radius,
                *self.server.map_extent(),
            )
            return
        with self._pose_ready:
            if self._posed:
                return  # the localizer has a pose: its own search uses the hint
            self._search = region
            self._pose_ready.notify()

    def _on_localizer_status(self, msg: NdtStatus) -> None:
        if msg.start_pending and self.config.pose_source == "odom":
            # A start the localizer carries while its map arrives (the vehicle drives on): the window goes with it.
            self._offer(PoseSample(msg.start_x, msg.start_y, msg.header.stamp.to_sec(), msg.start_yaw))
        if self.config.lost.max_half_side <= 0.0:
            return
        with self._pose_ready:
            # The window grows for a search only once its tiles have all arrived: a growth queued behind a window
            # still loading would only slow what the robot needs now.
            if msg.lost and msg.search_radius > 0.0 and msg.tiles_in_flight == 0:
                self._search = SearchRegion(msg.search_x, msg.search_y, msg.search_radius, msg.header.stamp.to_sec())
                self._tracking_again = False
            elif msg.match_accepted:
                self._search = None
                self._tracking_again = True
            else:
                return
            self._pose_ready.notify()

    def _frame_ok(self, frame_id: str) -> bool:
        if frame_id in ("", self.frame):
            return True
        rospy.logwarn_throttle(
            WARN_PERIOD, "ignoring a pose in frame '%s': poses must be in map_frame '%s'", frame_id, self.frame
        )
        return False

    def _offer(self, pose: PoseSample) -> None:
        with self._pose_ready:
            self._latest = pose
            self._posed = True
            self._pose_ready.notify()

    def _on_resend(self, _req) -> TriggerResponse:
        sent = self.send_reset(self.delta_pub.publish, increment=True)
        if sent is None:
            return TriggerResponse(success=False, message="no window yet: no pose has arrived")
        return TriggerResponse(success=True, message=f"revision {sent}: reset delta of the whole window")

    # ------------------------------------------------------------ worker
    def _run(self) -> None:
        while not rospy.is_shutdown():
            with self._pose_ready:
                if self._latest is None:
                    self._pose_ready.wait(0.5)
                pose, self._latest = self._latest, None
                search, self._search = self._search, None
                tracking_again, self._tracking_again = self._tracking_again, False
            if tracking_again:
                with self._lock:
                    self.server.end_search()  # the next pose is measured again: the window goes back to it
            self._poll_store()
            self._follow_directory()
            if search is not None:
                self._cover_search(search)
            self._maybe_serve_whole_map()
            if pose is not None:
                self._saved_pose.set([pose.x, pose.y, 0.0, 0.0, 0.0, pose.yaw or 0.0], pose.t)
                start = time.perf_counter()
                with self._lock:
                    served = self.server.on_pose(pose)
                if served is not None:
                    self._publish(served, start)

    def _cover_search(self, region: SearchRegion) -> None:
        """Serves the window that holds the lost localizer's search region (provider/lost_search.py)."""
        start = time.perf_counter()
        with self._lock:
            first = not self.server.lost.active
            served = self.server.on_search(region)
        if served is None:
            return
        if first:
            window = served.window
            rospy.logwarn(
                "the localizer is lost: the window grows to %.0f m x %.0f m around (%.1f, %.1f) m for its search",
                (window.i_max - window.i_min + 1) * self.s,
                (window.j_max - window.j_min + 1) * self.s,
                region.x,
                region.y,
            )
        self._publish(served, start)

    def _maybe_serve_whole_map(self) -> None:
        """With no pose and no hint start/search_timeout after start-up: the whole map, for the global search."""
        timeout = self.config.start.search_timeout
        with self._pose_ready:
            due = not (self._posed or self._whole_map_tried or self.server.lost.active)
        if not due or timeout <= 0.0 or time.monotonic() - self._started < timeout:
            return
        self._whole_map_tried = True
        area = self.server.map_area()
        if area > self.config.start.max_area:
            rospy.logwarn(
                "no pose and no hint %.1f s after start-up, and the map (%.2f km^2) is larger than start/max_area"
                " (%.2f km^2): waiting for initialpose or initialpose_hint",
                timeout,
                area / 1e6,
                self.config.start.max_area / 1e6,
            )
            return
        start = time.perf_counter()
        with self._lock:
            served = self.server.on_whole_map()
        if served is not None:
            rospy.logwarn(
                "no pose and no hint %.1f s after start-up: serving the whole map (%.2f km^2) for the global search",
                timeout,
                area / 1e6,
            )
            self._publish(served, start)

    def _poll_store(self) -> None:
        """Asks the map store for a new index revision when due (outside the lock: the network may be slow);
        _follow_directory then takes it up. Says when the server stops or starts answering."""
        if self.store is None or time.monotonic() < self._next_poll:
            return
        self._next_poll = time.monotonic() + self.store.config.poll_period
        try:
            self.store.poll_index()
        except (UserError, OSError) as err:
            rospy.logerr_throttle(WARN_PERIOD, "map store %s: new index not used: %s", self.store.url, err)
        status = self.store.status
        if not status.reachable:
            rospy.logwarn_throttle(
                WARN_PERIOD,
                "map store %s unreachable (%s): serving the tiles of index revision %s, retrying every %g s",
                status.url,
                status.last_error,
                status.revision,
                self.store.config.poll_period,
            )
        elif not self._store_reachable:
            rospy.loginfo("map store %s reachable (index revision %s)", status.url, status.revision)
        if status.reachable != self._store_reachable:
            self._store_reachable = status.reachable
            self._publish_status()

    def _follow_directory(self) -> None:
        """Sends the whole window again when the tile directory was rewritten (new index revision)."""
        try:
            with self._lock:
                changed = self.server.refresh()
        except (UserError, OSError) as err:
            rospy.logerr_throttle(WARN_PERIOD, "tile directory unusable, keeping the window as it is: %s", err)
            return
        if changed:
            rospy.logwarn(
                "tile directory %s changed (index revision %s): sending the whole window again",
                self.server.tiles.location,
                self.server.tiles.revision,
            )
            self.send_reset(self.delta_pub.publish, increment=True)
            if self.map_cloud is not None:
                self.map_cloud.changed(rospy.Time.now())

    def _publish(self, served: Served, start: float) -> None:
        """Publishes a window update; ``start``: perf_counter() when the update began."""
        pose, window, delta = served.pose, served.window, served.delta
        stamp = rospy.Time.from_sec(pose.t) if pose.t > 0.0 else rospy.Time.now()
        with self._lock:
            msg = self._delta_msg(stamp, window, served.first, delta.added, delta.removed, delta.prefetch)
            if served.changed:
                self._revision += 1
                msg.revision = self._revision
                self.delta_pub.publish(msg)
            loaded = len(self.server.tiles.loaded())
        self._report(pose, window, loaded)
        if self.map_cloud is not None and (served.first or delta.added or delta.removed):
            self.map_cloud.changed(stamp)
        update_ms = (time.perf_counter() - start) * 1e3
        self._last_status = provider_status(stamped(self.frame, stamp), window, msg, loaded, update_ms)
        self._publish_status()

    def _publish_status(self) -> None:
        """~status of the last window, with the map store's state (a change of it alone publishes it again)."""
        if self._last_status is None:
            return
        if self.store is not None:
            status = self.store.status
            self._last_status.store_reachable, self._last_status.store_error = status.reachable, status.last_error
        self.status_pub.publish(self._last_status)

    def _delta_msg(self, stamp, window: Window, reset: bool, added, removed, prefetch):
        return tile_delta(
            stamped(self.frame, stamp),
            self._revision,
            reset,
            self.s,
            window,
            self.server.tiles.location,
            self.server.tiles.revision,
            added,
            removed,
            prefetch,
        )

    def _window_paths(self) -> list:
        with self._lock:
            return self.server.tiles.paths()

    def _report(self, pose: PoseSample, window: Window, loaded: int) -> None:
        off_map = loaded == 0
        if off_map:
            rospy.logwarn_throttle(
                WARN_PERIOD,
                "pose (%.1f, %.1f) m is off the map: no tile in window i %d..%d, j %d..%d (the map spans"
                " x %.0f..%.0f m, y %.0f..%.0f m); publishing an empty window until the pose returns",
                pose.x,
                pose.y,
                *window.bounds,
                *self.server.map_extent(),
            )
        elif self._off_map:
            rospy.loginfo("pose (%.1f, %.1f) m is back on the map: %d tiles in the window", pose.x, pose.y, loaded)
        self._off_map = off_map

    def send_reset(self, publish, increment: bool) -> int | None:
        """Publishes the whole window as a reset delta through ``publish``; returns its revision, or
        None before the first window. ``increment``: a broadcast delta (new revision) rather than a
        catch-up for one new subscriber (current revision)."""
        with self._lock:
            whole = self.server.whole()
            if whole is None:
                return None
            if increment:
                self._revision += 1
            window, delta = whole
            publish(self._delta_msg(rospy.Time.now(), window, True, delta.added, [], delta.prefetch))
            return self._revision


def main() -> None:
    pin_mmap_threshold()  # map_cloud's tile buffers go back to the system once sent
    limit_arenas(1)  # before rospy starts its threads
    rospy.init_node("grid_puzzle_map_provider")
    try:

        def get(name, default):
            return rospy.get_param("~" + name, default)

        MapProviderNode(load_config(get), load_config(get, MapStoreConfig, "map_store/"))
    except UserError as err:
        rospy.logfatal("grid_puzzle_map_provider: %s", err)
        sys.exit(2)
    rospy.spin()
