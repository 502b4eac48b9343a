"""Modules only pip installs are imported where a feature needs them: without them, everything else runs, and the
feature that needs one says which package to install."""

import sys

import numpy as np
import pytest

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import read_pcd, write_pcd
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE


@pytest.fixture
def without_lzf(monkeypatch):
    """As on a robot with only what rosdep installs: `import lzf` fails."""
    monkeypatch.setitem(sys.modules, "lzf", None)


def _points(n: int) -> np.ndarray:
    points = np.zeros(n, dtype=XYZ_DTYPE)
    points["x"] = np.arange(n)
    return points


def test_binary_pcd_reads_and_writes_without_lzf(tmp_path, without_lzf):
    write_pcd(tmp_path / "a.pcd", _points(5), encoding="binary")
    assert read_pcd(tmp_path / "a.pcd").points["x"].tolist() == [0, 1, 2, 3, 4]


def test_binary_compressed_without_lzf_names_the_file_and_the_package(tmp_path, monkeypatch):
    path = tmp_path / "map.pcd"
    write_pcd(path, _points(5), encoding="binary_compressed")
    monkeypatch.setitem(sys.modules, "lzf", None)
    with pytest.raises(UserError, match=r"map\.pcd: a binary_compressed PCD needs .*pip install python-lzf"):
        read_pcd(path)
    with pytest.raises(UserError, match=r"writing a binary_compressed PCD needs .*python-lzf"):
        write_pcd(tmp_path / "out.pcd", _points(5), encoding="binary_compressed")
    assert not (tmp_path / "out.pcd").exists()


def test_ray_casting_without_embreex_names_the_package(monkeypatch):
    from grid_puzzle_localization.sim.meshes import Mesh
    from grid_puzzle_localization.sim.raycast import RayCaster

    monkeypatch.setitem(sys.modules, "embreex", None)
    monkeypatch.setitem(sys.modules, "embreex.rtcore_scene", None)
    with pytest.raises(UserError, match=r"gpm simulate.*embreex.*pip install embreex"):
        RayCaster(Mesh(np.zeros((3, 3), np.float32), np.array([[0, 1, 2]], np.int32), np.ones(1)))
