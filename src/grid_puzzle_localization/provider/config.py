"""Parameters of grid_puzzle_map_provider. The dataclasses hold the defaults (one place);
config/grid_puzzle_map_provider.yaml documents each parameter with its unit (a test keeps the two equal).
Nested dataclasses are parameter groups: ``window.n`` is the ROS parameter ``~window/n``."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.provider.window import WindowConfig

POSE_SOURCES = ("odom", "pose")


@dataclass(frozen=True)
class TilesConfig:
    dir: str = ""  # tile directory written by `gpm tile` (required)
    grid_size: float = 0.0  # [m] tile side s; 0 = take it from the index (required when there is none)


@dataclass(frozen=True)
class LostConfig:
    """While the localizer is lost (its status on `localizer_status`), the window grows to hold the region its
    search covers: the square of half side (search radius + n s) around the last accepted pose, capped."""

    max_half_side: float = 100.0  # [m] >= 0; largest half side of that square; 0 = the window never grows


@dataclass(frozen=True)
class StartConfig:
    """A start with no pose: none given, none saved in ~last_pose, and no hint on `initialpose_hint` (a hint alone is
    served as a search region of three standard deviations around it)."""

    # [s] >= 0; this long after start-up the whole map is served for the localizer's global search (set it with the
    # localizer's global_localization/auto_start_timeout); 0 = never
    search_timeout: float = 0.0
    max_area: float = 1.0e6  # [m^2] > 0; a larger map is not served whole: it needs a pose or a hint


@dataclass(frozen=True)
class ProviderConfig:
    tiles: TilesConfig = field(default_factory=TilesConfig)
    window: WindowConfig = field(default_factory=WindowConfig)
    lost: LostConfig = field(default_factory=LostConfig)
    start: StartConfig = field(default_factory=StartConfig)
    pose_source: str = "odom"  # odom: nav_msgs/Odometry on `odom`; pose: PoseWithCovarianceStamped on `pose`
    publish_map_cloud: bool = False  # publish the merged window on the latched `map_cloud` (read while subscribed)
    map_cloud_period: float = 1.0  # [s] publish map_cloud at most this often (the latest window); 0 = every change
    map_frame: str = "map"  # frame of the tiles, the incoming poses and every published cloud
    save_pose_rate: float = 0.5  # [Hz] write the newest pose to ~last_pose (0 = never); a respawn starts there

    def checked(self) -> ProviderConfig:
        """Raises UserError naming the first bad parameter; returns self with the window resolved."""
        if not self.tiles.dir:
            raise UserError("parameter tiles/dir is empty; set it to a tile directory written by `gpm tile`")
        if self.tiles.grid_size < 0.0:
            raise UserError(
                f"parameter tiles/grid_size must be > 0 m, or 0 to read it from the index (got {self.tiles.grid_size})"
            )
        if not self.map_cloud_period >= 0.0:
            raise UserError(f"parameter map_cloud_period must be >= 0 s (got {self.map_cloud_period})")
        if not (math.isfinite(self.lost.max_half_side) and self.lost.max_half_side >= 0.0):
            raise UserError(f"parameter lost/max_half_side must be >= 0 m (got {self.lost.max_half_side}); 0 = off")
        if not (math.isfinite(self.start.search_timeout) and self.start.search_timeout >= 0.0):
            raise UserError(f"parameter start/search_timeout must be >= 0 s (got {self.start.search_timeout}); 0 = off")
        if not (math.isfinite(self.start.max_area) and self.start.max_area > 0.0):
            raise UserError(f"parameter start/max_area must be > 0 m^2 (got {self.start.max_area})")
        if not (math.isfinite(self.save_pose_rate) and self.save_pose_rate >= 0.0):
            raise UserError(f"parameter save_pose_rate must be >= 0 Hz (got {self.save_pose_rate}); 0 = off")
        if self.pose_source not in POSE_SOURCES:
            raise UserError(f"parameter pose_source '{self.pose_source}' is unknown; use one of {POSE_SOURCES}")
        return dataclasses.replace(self, window=self.window.resolved())


def parameter_defaults(cls: type = ProviderConfig, prefix: str = "") -> dict[str, Any]:
    """Flat ``{"group/name": default}`` of a (nested) config dataclass."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        default = f.default_factory() if f.default is dataclasses.MISSING else f.default
        if dataclasses.is_dataclass(default):
            out.update(parameter_defaults(type(default), f"{prefix}{f.name}/"))
        else:
            out[prefix + f.name] = default
    return out


def load_config(get: Callable[[str, Any], Any], cls: type = ProviderConfig, prefix: str = ""):
    """Builds ``cls`` from ``get(name, default)`` (e.g. rospy.get_param on ``~name``), converting each
    value to its default's type; raises UserError naming a parameter of the wrong type."""
    values = {}
    for f in dataclasses.fields(cls):
        default = f.default_factory() if f.default is dataclasses.MISSING else f.default
        name = prefix + f.name
        if dataclasses.is_dataclass(default):
            values[f.name] = load_config(get, type(default), name + "/")
            continue
        value = get(name, default)
        values[f.name] = _coerce(name, value, type(default))
    return cls(**values)


def _coerce(name: str, value: Any, kind: type) -> Any:
    ok = {
        bool: isinstance(value, bool),
        int: isinstance(value, int) and not isinstance(value, bool),
        float: isinstance(value, (int, float)) and not isinstance(value, bool),
        str: isinstance(value, str),
    }[kind]
    if not ok:
        raise UserError(f"parameter {name} must be a {kind.__name__} (got {value!r})")
    return kind(value)
