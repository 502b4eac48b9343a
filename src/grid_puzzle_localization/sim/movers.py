"""Moving objects (pedestrians, cars) that appear in the localization scans but not in the prior map.

Each mover follows its own random route over the path graph with a walking or driving profile
(pedestrians 1.2 m/s on the left, cars 6 m/s in the right lane with stops). For a sweep
the movers are frozen at the sweep's middle time (they move at most 0.6 m during a 0.1 s sweep) and
meshed; movers within ``CLEARANCE`` of the sensor are left out so the sensor is never inside one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from grid_puzzle_localization.sim import meshes
from grid_puzzle_localization.sim.meshes import Mesh, MeshBuilder
from grid_puzzle_localization.sim.trajectory import MotionProfile, Trajectory, make_trajectory, plan_route
from grid_puzzle_localization.sim.worlds import Ground, World, car

PEDESTRIAN = MotionProfile(0.0, 1.2, 1.0, -0.8, 0.8, 1.0, 0.6, 0.1, (1.0, 5.0), 0.0, 0.1, 0.25)
CAR = MotionProfile(0.0, 6.0, 9.0, 2.5, 1.5, 2.5, 2.0, 0.3, (3.0, 10.0), 8.0, 0.25, 0.2)
# Pedestrians keep left: beside the walkway centre in the courtyard, on the sidewalk of narrow streets.
PEDESTRIAN_LANE = {"courtyard": -0.8, "urban": -6.0}  # [m] right of the centre line
CLEARANCE = {"pedestrian": 1.0, "car": 4.0}  # [m] horizontal, from the sensor
DEFAULT_COUNT = {"courtyard": {"pedestrian": 12}, "urban": {"car": 12, "pedestrian": 8}}  # at scale 1


@dataclass(frozen=True)
class Movers:
    """Mover trajectories (times as for the localization run), their kinds and reflectivities."""

    ground: Ground
    trajectories: list[Trajectory]
    kinds: list[str]
    reflectivity: np.ndarray

    def mesh_at(self, t: float, sensor_xy: np.ndarray) -> Mesh | None:
        """The movers at time ``t`` [s] as one mesh, without those near ``sensor_xy``; None if none remain."""
        b = MeshBuilder()
        count = 0
        for traj, kind, refl in zip(self.trajectories, self.kinds, self.reflectivity, strict=True):
            pos, quat = traj.interpolate(np.array([t]))
            x, y = float(pos[0, 0]), float(pos[0, 1])
            if np.hypot(x - sensor_xy[0], y - sensor_xy[1]) < CLEARANCE[kind]:
                continue
            qx, qy, qz, qw = quat[0]
            yaw = float(np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz)))
            if kind == "car":
                car(b, self.ground, x, y, yaw, float(refl))
            else:
                z = float(self.ground.height(np.array(x), np.array(y)))
                b.add(meshes.box(x - 0.15, y - 0.25, x + 0.15, y + 0.25, z, z + 1.75, yaw), float(refl))
            count += 1
        return b.build() if count else None


def make_movers(world: World, scale: float, duration: float, count: int | None, rng: np.random.Generator) -> Movers:
    """Movers for ``duration`` seconds: the world's default mix times ``scale`` (at least one), or
    ``count`` of them in the same proportions."""
    mix = DEFAULT_COUNT[world.name]
    total = sum(mix.values())
    wanted = max(1, round(total * scale)) if count is None else count
    kinds = [k for k, n in mix.items() for _ in range(n)]
    kinds = [kinds[(i * total) // wanted % total] for i in range(wanted)]  # keeps the mix's proportions
    trajectories = []
    for kind in kinds:
        prof = CAR if kind == "car" else replace(PEDESTRIAN, lane_offset=PEDESTRIAN_LANE[world.name])
        length = prof.speed_avg * duration + 20.0
        route = plan_route(world.graph, length, rng)
        trajectories.append(make_trajectory(world.graph, world.ground, route, prof, length, rng))
    return Movers(world.ground, trajectories, kinds, rng.uniform(0.2, 0.9, len(kinds)))
