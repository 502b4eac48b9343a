"""One simulated scenario, end to end: world, trajectories, sweeps, IMU, prior map, output directory.

The output directory holds ``scenario.yaml`` (every parameter and the seed), ``ground_truth.tum``
(base_link in map, TUM format, 100 Hz), ``scenario.bag`` and ``global_map.pcd``. It is built in a
hidden temporary directory beside the target and renamed into place only when complete, so an
interrupt or a full disk never leaves a directory that looks finished. The same configuration gives
byte-identical files: all randomness comes from ``seed`` and every bag stamp is set explicitly, starting
at ``start_time`` (seconds since the epoch).
"""

from __future__ import annotations

import math
import os
import sys
import time
from contextlib import closing
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation import trajectory as tum
from grid_puzzle_localization.pcd import PcdStreamWriter
from grid_puzzle_localization.sim.imu import ImuNoise, simulate_imu, true_motion
from grid_puzzle_localization.sim.lidar import Mount, SweepSimulator
from grid_puzzle_localization.sim.mapping import MAP_DTYPE, DriftBounds, VoxelMap, drifted, to_map
from grid_puzzle_localization.sim.movers import Movers, make_movers
from grid_puzzle_localization.sim.ordered import ordered_map
from grid_puzzle_localization.sim.raycast import RayCaster
from grid_puzzle_localization.sim.recording_faults import YawSwing, check_gaps, in_gaps, with_yaw_swing
from grid_puzzle_localization.sim.sensors import DEFAULT_SENSOR, get_sensor
from grid_puzzle_localization.sim.trajectory import RATE, Trajectory, localization_trajectory, mapping_trajectory
from grid_puzzle_localization.sim.worlds import check_world, make_world
from grid_puzzle_localization.util.atomic import atomic_directory, check_output_dir

# base_link -> lidar per platform [m]: a backpack for the courtyard walk, a roof mount for the car.
MOUNTS = {"courtyard": (0.2, 0.0, 1.3), "urban": (0.3, 0.0, 1.8), "corridor": (0.3, 0.0, 1.8)}
DEFAULT_MAP_LEAF = {"courtyard": 0.05, "urban": 0.1, "corridor": 0.1}  # [m]
GROUND_TRUTH_RATE = 100.0  # [Hz] ground_truth topic and ground_truth.tum
FILES = ("scenario.yaml", "ground_truth.tum", "scenario.bag", "global_map.pcd")


@dataclass(frozen=True)
class ScenarioConfig:
    """Parameters of ``gpm simulate``; None picks the world's default."""

    world: str = "courtyard"
    sensor: str | None = None  # hdl32 | livox
    seed: int = 0
    scale: float = 1.0  # world extent and route length factor, (0.2, 1]
    duration: float | None = None  # [s] of the localization run; None: the whole route
    map_leaf: float | None = None  # [m] voxel size of the prior map
    start_time: float = 1.7e9  # [s] bag time of the first sample
    threads: int = 2  # sweep worker threads (the output does not depend on it)
    movers: int | None = None  # moving pedestrians/cars in the scans (not in the map); None: world default
    drift: DriftBounds = field(default_factory=DriftBounds)
    imu_noise: ImuNoise = field(default_factory=ImuNoise)
    imu: bool = True  # False: no imu topic (a LiDAR-only recording)
    yaw_swing: YawSwing | None = None  # hand-held: the localization run's yaw swings (the map run does not)
    scan_rate: float | None = None  # [Hz] scans written to the bag (every n-th sweep); None: every sweep
    gaps: tuple[tuple[float, float], ...] = ()  # (start, length) [s]: nothing recorded in these intervals

    @classmethod
    def from_parameters(cls, parameters: dict) -> ScenarioConfig:
        """The configuration a scenario.yaml's ``parameters`` describe (as ``gpm simulate`` wrote them)."""
        p = dict(parameters)
        p["drift"] = DriftBounds(**p.get("drift", {}))
        p["imu_noise"] = ImuNoise(**p.get("imu_noise", {}))
        p["yaw_swing"] = YawSwing(**p["yaw_swing"]) if p.get("yaw_swing") else None
        p["gaps"] = tuple(tuple(g) for g in p.get("gaps", ()))
        return cls(**p)

    def resolved(self) -> ScenarioConfig:
        """A copy with defaults filled in, after checking every parameter (UserError if bad)."""
        sensor = self.sensor or DEFAULT_SENSOR[check_world(self.world)]
        get_sensor(sensor)
        if self.duration is not None and not (math.isfinite(self.duration) and self.duration >= 0.5):
            raise UserError(f"--duration must be at least 0.5 s (got {self.duration}); for example --duration 30")
        leaf = self.map_leaf if self.map_leaf is not None else DEFAULT_MAP_LEAF[self.world]
        if not (0.01 <= leaf <= 2.0):
            raise UserError(f"--map-density (voxel size) must be between 0.01 and 2 m (got {leaf})")
        if self.seed < 0:
            raise UserError(f"--seed must be a non-negative integer (got {self.seed})")
        if self.threads < 1:
            raise UserError(f"--threads must be at least 1 (got {self.threads})")
        if self.movers is not None and self.movers < 0:
            raise UserError(f"--movers must be a non-negative count (got {self.movers})")
        if self.yaw_swing is not None:
            self.yaw_swing.check()
        if self.scan_rate is not None:
            scan_every(get_sensor(sensor).rate, self.scan_rate)
        return replace(self, sensor=sensor, map_leaf=leaf)


@dataclass
class Summary:
    """What a run produced and how long each pass took: wall-clock seconds and CPU seconds of the
    process (all threads), so figures from a shared machine can be judged."""

    directory: Path
    duration: float
    sweeps: int
    rays: int
    points: int
    map_sweeps: int
    map_rays: int
    map_points_in: int  # points accumulated into the voxel filter
    map_points: int  # points in global_map.pcd
    seconds_localization: float
    seconds_mapping: float
    cpu_seconds_localization: float
    cpu_seconds_mapping: float


def scan_every(sensor_rate: float, scan_rate: float | None) -> int:
    """Every how many sweeps a scan is written, for ``scan_rate`` [Hz] (UserError unless it divides the
    sensor's rate)."""
    if scan_rate is None:
        return 1
    stride = round(sensor_rate / scan_rate) if scan_rate > 0 else 0
    if stride < 1 or abs(stride * scan_rate - sensor_rate) > 1e-9 * sensor_rate:
        raise UserError(f"--scan-rate {scan_rate} Hz must divide the sensor's {sensor_rate:g} Hz (e.g. 2, 5 or 10)")
    return stride


def _rng(seed: int, *stream: int) -> np.random.Generator:
    return np.random.default_rng([seed, *stream])


def _progress(total: int, desc: str, show: bool):
    return tqdm(total=total, desc=desc, unit="sweep", file=sys.stderr, disable=not show, mininterval=1.0)


def _sample_stamps_ns(t0: float, samples: np.ndarray) -> np.ndarray:
    """Exact stamps [ns] of trajectory samples (indices at RATE) of a run starting at ``t0`` [s]."""
    return round(t0 * 1e9) + samples * round(1e9 / RATE)


def _write_tum(path: Path, t0: float, traj: Trajectory) -> None:
    """base_link in map at GROUND_TRUTH_RATE, stamped in exact nanoseconds like the bag."""
    step = round(RATE / GROUND_TRUTH_RATE)
    i = np.arange(0, len(traj.position), step)
    stamps_ns = _sample_stamps_ns(t0, i)
    truth = tum.make_trajectory(stamps_ns * 1e-9, traj.position[i], traj.quat[i], source="ground truth")
    tum.write_tum(path, truth, stamps_ns)


def _write_bag(
    path: Path, cfg: ScenarioConfig, sim: SweepSimulator, traj: Trajectory, mount: Mount, movers: Movers, show: bool
):
    from grid_puzzle_localization.ros.bags.writer import BagNames, ScenarioBag

    sensor, t0 = sim.sensor, cfg.start_time
    imu = simulate_imu(traj, _rng(cfg.seed, 6), cfg.imu_noise)
    gyro_true, _, velocity = true_motion(traj)
    vel_body = Rotation.from_quat(traj.quat).inv().apply(velocity)
    gyro_var = (cfg.imu_noise.gyro_noise_density**2) * RATE
    accel_var = (cfg.imu_noise.accel_noise_density**2) * RATE
    gt_step = round(RATE / GROUND_TRUTH_RATE)
    samples_per_sweep = round(RATE / sensor.rate)
    n_sweeps = int(np.floor(traj.duration * sensor.rate + 1e-9))
    stride = scan_every(sensor.rate, cfg.scan_rate)
    every = np.arange(0, n_sweeps, stride)
    scans = every[~in_gaps(every / sensor.rate, cfg.gaps)]  # sweeps written, by the time they start

    def sweep_cloud(j: int) -> tuple[int, np.ndarray]:
        k = int(scans[j])
        sweep = sensor.sweep(k)
        t_mid = (k + 0.5) / sensor.rate
        frozen = movers.mesh_at(t_mid, traj.interpolate(np.array([t_mid]))[0][0, :2])
        return len(sweep.dt), sim.simulate(traj, k / sensor.rate, sweep, _rng(cfg.seed, 4, k), frozen)

    rays = points = 0
    clouds = ordered_map(sweep_cloud, len(scans), cfg.threads)
    # closing(clouds): an error stops the queued sweeps at once
    with ScenarioBag(str(path), BagNames()) as bag, _progress(len(scans), "localization run", show) as bar, closing(
        clouds
    ):
        bag.write_tf_static(t0, mount.translation, Rotation.from_matrix(mount.rotation).as_quat())

        def motion(i0: int, i1: int) -> None:
            """IMU and ground truth samples i0 .. i1 - 1 (ground truth every gt_step-th sample) outside the gaps."""
            i = np.arange(i0, min(i1, len(traj.position)))
            i = i[~in_gaps(i / RATE, cfg.gaps)]
            if cfg.imu:
                bag.write_imu(_sample_stamps_ns(t0, i), imu.gyro[i], imu.accel[i], gyro_var, accel_var)
            g = i[i % gt_step == 0]
            stamps = _sample_stamps_ns(t0, g)
            bag.write_ground_truth(stamps, traj.position[g], traj.quat[g], vel_body[g], gyro_true[g])

        done = 0  # trajectory samples written
        for j, (n_rays, cloud) in enumerate(clouds):
            k = int(scans[j])
            motion(done, (k + 1) * samples_per_sweep)
            done = (k + 1) * samples_per_sweep
            start, end = _sample_stamps_ns(t0, np.array([k, k + 1]) * samples_per_sweep)
            bag.write_points(int(start), int(end), cloud)
            rays += n_rays
            points += len(cloud)
            bar.update()
        motion(done, len(traj.position))
    return len(scans), rays, points


def runs(cfg: ScenarioConfig, world) -> tuple[Trajectory, Trajectory]:
    """The localization run (before any yaw swing) and the mapping run of the resolved ``cfg`` in ``world``."""
    loc = localization_trajectory(world, cfg.scale, _rng(cfg.seed, 1))
    if cfg.duration is not None:
        loc = loc.truncated(cfg.duration)
    return loc, mapping_trajectory(world, loc, _rng(cfg.seed, 2))  # the map run is not hand-held


def mapping_estimate(cfg: ScenarioConfig, mapping: Trajectory) -> Trajectory:
    """The drifted pose estimate the mapping run's sweeps were placed at in the prior map."""
    return drifted(mapping, cfg.drift, _rng(cfg.seed, 3))


def _write_map(path: Path, cfg: ScenarioConfig, sim: SweepSimulator, traj: Trajectory, mount: Mount, show: bool):
    estimate = mapping_estimate(cfg, traj)
    voxels = VoxelMap(cfg.map_leaf)
    sensor = sim.sensor
    n_sweeps = int(np.floor(traj.duration * sensor.rate + 1e-9))

    def placed_sweep(k: int) -> tuple[int, np.ndarray, np.ndarray]:
        sweep = sensor.sweep(k)
        cloud = sim.simulate(traj, k / sensor.rate, sweep, _rng(cfg.seed, 5, k))
        return len(sweep.dt), to_map(estimate, mount, k / sensor.rate, cloud), cloud["intensity"]

    rays = points = 0
    swept = ordered_map(placed_sweep, n_sweeps, cfg.threads)
    with _progress(n_sweeps, "mapping run", show) as bar, closing(swept):
        for n_rays, xyz, intensity in swept:
            voxels.add(xyz, intensity)
            rays += n_rays
            points += len(xyz)
            bar.update()
    with PcdStreamWriter(path, MAP_DTYPE) as writer:
        for chunk in voxels.chunks():
            writer.append(chunk)
        count = writer.points
    return n_sweeps, rays, points, count


def _describe(cfg: ScenarioConfig, world, loc: Trajectory, mapping: Trajectory, mount: Mount, movers: Movers) -> dict:
    sensor = get_sensor(cfg.sensor)
    params = asdict(cfg)
    params.pop("threads")
    params["gaps"] = [list(g) for g in cfg.gaps]
    return {
        "scenario": cfg.world,
        "parameters": params,
        "world": {"extent_m": [float(v) for v in world.extent], "triangles": len(world.mesh.faces)},
        "sensor": {k: (v if not isinstance(v, float) else float(v)) for k, v in asdict(sensor).items()},
        "mount_base_link_to_lidar": {
            "translation_m": [float(v) for v in mount.translation],
            "quaternion_xyzw": [0.0, 0.0, 0.0, 1.0],
        },
        "localization_run": {
            "duration_s": float(loc.duration),
            "length_m": round(loc.length(), 3),
            "start_time_s": float(cfg.start_time),
        },
        "movers": {kind: movers.kinds.count(kind) for kind in sorted(set(movers.kinds))},
        "mapping_run": {"duration_s": float(mapping.duration), "length_m": round(mapping.length(), 3)},
        "frames": {"map": "map", "base": "base_link", "lidar": "lidar"},
        "topics": {
            "points": "points",
            **({"imu": "imu"} if cfg.imu else {}),
            "ground_truth": "ground_truth",
            "tf_static": "/tf_static",
        },
        "files": list(FILES),
    }


def generate(cfg: ScenarioConfig, out_dir: str | os.PathLike, force: bool = False, progress: bool = True) -> Summary:
    """Simulates the scenario ``cfg`` into ``out_dir`` (absent or empty, or replaced with ``force``)."""
    cfg = cfg.resolved()
    world = make_world(cfg.world, cfg.seed, cfg.scale)
    out = Path(out_dir).absolute()
    check_output_dir(out, force)
    loc, mapping = runs(cfg, world)
    check_gaps(cfg.gaps, loc.duration)
    if cfg.yaw_swing is not None:
        loc = with_yaw_swing(loc, cfg.yaw_swing)
    movers = make_movers(world, cfg.scale, loc.duration, cfg.movers, _rng(cfg.seed, 7))
    mount = Mount(np.array(MOUNTS[cfg.world]), np.eye(3))
    with atomic_directory(out, durable=True) as tmp, RayCaster(world.mesh, threads=1) as caster:
        sim = SweepSimulator(world.mesh, caster, get_sensor(cfg.sensor), mount)
        (tmp / "scenario.yaml").write_text(
            yaml.safe_dump(_describe(cfg, world, loc, mapping, mount, movers), sort_keys=False)
        )
        _write_tum(tmp / "ground_truth.tum", cfg.start_time, loc)
        start, cpu_start = time.perf_counter(), time.process_time()
        sweeps, rays, points = _write_bag(tmp / "scenario.bag", cfg, sim, loc, mount, movers, progress)
        mid, cpu_mid = time.perf_counter(), time.process_time()
        map_sweeps, map_rays, map_in, map_points = _write_map(
            tmp / "global_map.pcd", cfg, sim, mapping, mount, progress
        )
        end, cpu_end = time.perf_counter(), time.process_time()
    return Summary(
        out,
        loc.duration,
        sweeps,
        rays,
        points,
        map_sweeps,
        map_rays,
        map_in,
        map_points,
        mid - start,
        end - mid,
        cpu_mid - cpu_start,
        cpu_end - cpu_mid,
    )
