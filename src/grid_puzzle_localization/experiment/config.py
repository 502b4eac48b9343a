"""Configuration of an experiment run: inputs, modes, window presets, playback and monitoring."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from grid_puzzle_localization.blocks.builder import BlockConfig
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.experiment.modes import DEFAULT_MODES, MODES
from grid_puzzle_localization.experiment.start import START_MODES, StartSetting
from grid_puzzle_localization.provider.window import PRESETS as PAPER_WINDOWS

FUSIONS = ("none", "sliding_window", "auto")  # the localizer's fusion/mode


@dataclass(frozen=True)
class WindowPreset:
    """Grid puzzle window: half side n [tiles], heading extension k [tiles], tile side s [m]."""

    n: int
    k: int
    grid_size_m: float


# The paper's presets (Section IV, n and k from the window module, s = 2 m), and a small one for the
# demo and the tests.
PAPER_GRID_SIZE_M = 2.0
PRESETS: dict[str, WindowPreset] = {
    **{name: WindowPreset(n, k, PAPER_GRID_SIZE_M) for name, (n, k) in PAPER_WINDOWS.items()},
    "demo": WindowPreset(8, 5, PAPER_GRID_SIZE_M),
}


@dataclass(frozen=True)
class NodeRoles:
    """ROS node names whose processes play each role (the nodelet runs inside its manager)."""

    localizer: str = "/localizer_manager"  # also the provider's process in grid_puzzle mode (a nodelet)
    map_provider: str = "/grid_puzzle_map_provider"  # grid_puzzle_rospy: its process; grid_puzzle: its loader
    block_server: str = "/block_map_server"  # the block_map mode's map provider
    recorder: str = "/trajectory_recorder"


@dataclass
class ExperimentConfig:
    out_dir: Path
    bag: Path
    global_map: Path
    ground_truth: Path | None = None
    tiles: Path | str | None = None  # a tile directory or a map store URL; None: cut from global_map into out_dir
    blocks: Path | None = None  # block map directory from `gpm blocks`; None: built from global_map along ground_truth
    block_size_m: float = BlockConfig.block_size  # S of the blocks built when blocks is None
    submaps: Path | None = None  # fixed-size submaps of side S for the storage table; None: cut into out_dir
    modes: list[str] = field(default_factory=lambda: list(DEFAULT_MODES))
    preset: str = "demo"
    window: WindowPreset = PRESETS["demo"]
    rate: float = 1.0  # bag playback speed, times real time
    monitor_interval_s: float = 0.5
    # Runs of each mode, interleaved (modes.interleaved_runs); the report gives the median and the spread. One run's
    # CPU varies by tenths of a point on a 2-core machine, as much as the difference between modes.
    repeats: int = 1
    max_time_diff_s: float = 0.05  # pose association tolerance
    startup_timeout_s: float = 60.0
    settle_s: float = 2.0  # after the nodes are up, and after the bag ends
    empty_map_s: float = 20.0  # [s] of the bag each mode also plays against an empty map (its floor); 0 = skip
    ndt_threads: int | None = None  # OpenMP threads of the NDT, 0 = all cores; None: the localizer's default
    fusion: str | None = None  # FUSIONS: pose tracking past the NDT match; None: the localizer's default
    initial_pose: list[float] | None = None  # x y z roll pitch yaw [m, rad]; None: first ground-truth pose
    start: StartSetting = field(default_factory=StartSetting)  # what the localizer is given (experiment.start)
    # [s] the localizer's global_localization/auto_start_timeout; None: the localizer's own (0, never) with a start
    # pose, and start_search_timeout_s without one (hint, none), as the localizer would otherwise never search. No
    # pose comes in these runs (a hint is latched before the first scan), so the search starts a scan period in.
    global_search_timeout_s: float | None = None
    start_search_timeout_s: float = 0.1
    # Where the hint is published: the localizer subscribes to initialpose_hint (relative), as the providers do.
    hint_topic: str = "initialpose_hint"
    roles: NodeRoles = field(default_factory=NodeRoles)
    launch_file: str = "localization.launch"  # of this package, or an absolute path
    localizer_status_topic: str = "/ndt_localizer/status"  # the localizer nodelet's NdtStatus (per-scan times)
    scenario_name: str = "custom"

    def check(self) -> None:
        """Raises UserError for a setting that cannot work, naming it."""
        for mode in self.modes:
            if mode not in MODES:
                raise UserError(f"unknown mode '{mode}' (use {', '.join(MODES)})")
        if not self.modes:
            raise UserError(f"give at least one mode (--modes {' '.join(DEFAULT_MODES)})")
        if not self.rate > 0:
            raise UserError(f"--rate must be > 0 (got {self.rate})")
        if self.repeats < 1:
            raise UserError(f"--repeats must be >= 1, the runs of each mode (got {self.repeats})")
        if not self.monitor_interval_s > 0:
            raise UserError(f"--interval must be > 0 s (got {self.monitor_interval_s})")
        for label, path in (("bag", self.bag), ("global map", self.global_map), ("ground truth", self.ground_truth)):
            if path is not None and not Path(path).is_file():
                raise UserError(f"{label} {path} does not exist")
        if "block_map" in self.modes and self.blocks is None and self.ground_truth is None:
            raise UserError(
                "block_map mode needs --blocks DIR (from `gpm blocks`), or ground truth to build them from the map"
            )
        if self.ndt_threads is not None and self.ndt_threads < 0:
            raise UserError(f"--ndt-threads must be >= 0, 0 = all cores (got {self.ndt_threads})")
        if self.fusion is not None and self.fusion not in FUSIONS:
            raise UserError(f"unknown fusion '{self.fusion}' (use {', '.join(FUSIONS)})")
        if not self.empty_map_s >= 0:
            raise UserError(f"--empty-map-seconds must be >= 0 (got {self.empty_map_s})")
        if not self.block_size_m > 0:
            raise UserError(f"--block-size must be > 0 m (got {self.block_size_m})")
        if self.initial_pose is None and self.ground_truth is None and self.start.mode != "none":
            raise UserError(
                "without ground truth, give the start pose: --initial-pose X Y Z ROLL PITCH YAW (or --start none)"
            )
        if self.initial_pose is not None and len(self.initial_pose) != 6:
            raise UserError(f"--initial-pose needs 6 numbers x y z roll pitch yaw (got {self.initial_pose})")
        start = self.start
        if start.mode not in START_MODES:
            raise UserError(f"unknown start '{start.mode}' (use --start {' | '.join(START_MODES)})")
        if start.mode != "pose" and (start.offset_m or start.offset_deg):
            raise UserError(f"--start-offset moves the start pose: use it with --start pose (got --start {start.mode})")
        if not start.offset_m >= 0:
            raise UserError(f"--start-offset: the distance must be >= 0 m (got {start.offset_m})")
        if not start.hint_sigma_m >= 0:
            raise UserError(f"--hint-sigma must be >= 0 m (got {start.hint_sigma_m})")
        if start.mode != "pose" and "block_map" in self.modes:
            raise UserError(f"block_map mode starts its block server from a pose: use --start pose (got {start.mode})")
        if self.global_search_timeout_s is not None and not self.global_search_timeout_s >= 0:
            raise UserError(f"--global-search-timeout must be >= 0 s, 0 = never (got {self.global_search_timeout_s})")
        if start.mode != "pose" and self.global_search_timeout_s == 0:
            raise UserError(f"--start {start.mode} gives no pose: the localizer needs --global-search-timeout > 0")

    def search_timeout_s(self) -> float | None:
        """The localizer's global_localization/auto_start_timeout for this run; None: its own default."""
        if self.global_search_timeout_s is not None:
            return self.global_search_timeout_s
        return None if self.start.mode == "pose" else self.start_search_timeout_s
