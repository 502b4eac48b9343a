"""Moving objects (pedestrians, cars) that appear in the localization scans but not in the prior map.

Each mover follows its own random route over the path graph with a walking or driving profile
(pedestrians 1.2 m/s on the left, cars 6 m/s in the right lane with stops). For a sweep
the movers are frozen at the sweep's middle time (they move at most 0.6 m during a 0.1 s sweep) and
meshed; movers within ``CLEARANCE`` of the sensor are left out so the sensor is never inside one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from grid_puzzle_localization.sim import meshes
from grid_puzzle_localization.sim.meshes import Mesh, MeshBuilder
from grid_puzzle_localization.sim.trajectory import RATE, MotionProfile, Trajectory, make_trajectory, plan_route
from grid_puzzle_localization.sim.worlds import Ground, World, car
from grid_puzzle_localization.util.iteration import zip_equal

PEDESTRIAN = MotionProfile(0.0, 1.2, 1.0, -0.8, 0.8, 1.0, 0.6, 0.1, (1.0, 5.0), 0.0, 0.1, 0.25)
CAR = MotionProfile(0.0, 6.0, 9.0, 2.5, 1.5, 2.5, 2.0, 0.3, (3.0, 10.0), 8.0, 0.25, 0.2)
# Pedestrians keep left: beside the walkway centre in the courtyard, on the sidewalk of narrow streets.
PEDESTRIAN_LANE = {"courtyard": -0.8, "urban": -6.0}  # [m] right of the centre line
CLEARANCE = {"pedestrian": 1.0, "car": 4.0}  # [m] horizontal, from the sensor
# At scale 1. The tunnel has none: its one road has no room to turn, so a random route could not continue.
DEFAULT_COUNT = {"courtyard": {"pedestrian": 12}, "urban": {"car": 12, "pedestrian": 8}, "corridor": {}}


def _templates() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Vertices (float64, centred on the origin, heading +x, standing on z = 0) and faces of each kind."""
    flat = Ground(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
    shapes = {"car": MeshBuilder(), "pedestrian": MeshBuilder()}
    car(shapes["car"], flat, 0.0, 0.0, 0.0, 0.0)
    shapes["pedestrian"].add(meshes.box(-0.15, -0.25, 0.15, 0.25, 0.0, 1.75), 0.0)
    return {kind: (b.build().vertices.astype(np.float64), b.build().faces) for kind, b in shapes.items()}


_TEMPLATES = _templates()


@dataclass(frozen=True)
class Movers:
    """Mover trajectories (times as for the localization run), their kinds and reflectivities."""

    ground: Ground
    trajectories: list[Trajectory]
    kinds: list[str]
    reflectivity: np.ndarray

    @cached_property
    def _yaw(self) -> list[np.ndarray]:
        """Unwrapped heading of each mover at its trajectory samples [rad]."""
        return [np.unwrap(traj.yaw()) for traj in self.trajectories]

    def mesh_at(self, t: float, sensor_xy: np.ndarray) -> Mesh | None:
        """The movers at time ``t`` [s] as one mesh, without those near ``sensor_xy``; None if none remain."""
        vertices, faces, reflectivity = [], [], []
        count = 0
        for traj, yaw, kind, refl in zip_equal(self.trajectories, self._yaw, self.kinds, self.reflectivity):
            f = min(max(t * RATE, 0.0), len(yaw) - 1.0)
            i = min(int(f), len(yaw) - 2)
            w = f - i
            x, y = traj.position[i, :2] * (1 - w) + traj.position[i + 1, :2] * w
            if np.hypot(x - sensor_xy[0], y - sensor_xy[1]) < CLEARANCE[kind]:
                continue
            heading = yaw[i] * (1 - w) + yaw[i + 1] * w
            c, s = np.cos(heading), np.sin(heading)
            local, tri = _TEMPLATES[kind]
            z = float(self.ground.height(np.array(x), np.array(y)))
            vertices.append(local @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) + np.array([x, y, z]))
            faces.append(tri + count)
            reflectivity.append(np.full(len(tri), refl, dtype=np.float32))
            count += len(local)
        if not count:
            return None
        return Mesh(
            np.concatenate(vertices).astype(np.float32),
            np.concatenate(faces).astype(np.int32),
            np.concatenate(reflectivity),
        )


def make_movers(world: World, scale: float, duration: float, count: int | None, rng: np.random.Generator) -> Movers:
    """Movers for ``duration`` seconds: the world's default mix times ``scale`` (at least one), or
    ``count`` of them in the same proportions."""
    mix = DEFAULT_COUNT[world.name]
    total = sum(mix.values())
    if total == 0:
        return Movers(world.ground, [], [], np.zeros(0))
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
