"""First-hit ray casting against a world mesh with Intel Embree (through the ``embreex`` bindings).

Embree builds the BVH once; :meth:`RayCaster.cast` splits a batch over threads (embreex releases the
GIL while tracing), so the result does not depend on the thread count.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from grid_puzzle_localization.sim.meshes import Mesh
from grid_puzzle_localization.util.iteration import pairwise
from grid_puzzle_localization.util.pip_only import import_pip_only

_MIN_RAYS_PER_THREAD = 20000


class RayCaster:
    """Casts rays against ``mesh``; ``threads`` worker threads share each batch."""

    def __init__(self, mesh: Mesh, threads: int = 2) -> None:
        needed_for = "Ray casting (`gpm simulate`)"
        self._scene = import_pip_only("embreex.rtcore_scene", "embreex", needed_for).EmbreeScene()
        meshes = import_pip_only("embreex.mesh_construction", "embreex", needed_for)
        # embreex keeps a reference to the triangle buffer it was given.
        self._triangles = np.ascontiguousarray(mesh.triangles, dtype=np.float32)
        meshes.TriangleMesh(self._scene, self._triangles)
        self.threads = max(1, int(threads))
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self) -> RayCaster:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out = self._scene.run(origins, directions, output=1)
        return out["tfar"], out["primID"]

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance along each unit ``direction`` to the first triangle [m] (float32, inf on a miss) and
        the hit triangle's index (int32, -1 on a miss). ``origins`` and ``directions`` are (n, 3)."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        n = len(o)
        parts = min(self.threads, max(1, n // _MIN_RAYS_PER_THREAD))
        if parts == 1 or self._pool is None:
            t, prim = self._cast(o, d)
        else:
            bounds = np.linspace(0, n, parts + 1).astype(int)
            jobs = [self._pool.submit(self._cast, o[a:b], d[a:b]) for a, b in pairwise(bounds)]
            results = [j.result() for j in jobs]
            t = np.concatenate([r[0] for r in results])
            prim = np.concatenate([r[1] for r in results])
        return np.where(prim >= 0, t, np.float32(np.inf)), prim
