"""How an experiment starts the localizer (`gpm experiment --start`), pure: no ROS.

- ``pose``: the start pose (the first ground-truth pose, or ``--initial-pose``) as the localizer's ``~initial_pose``
  and, latched, on ``initialpose``; ``--start-offset METRES DEGREES`` moves it by that distance in a seeded random
  direction and turns its yaw by that angle (a wrong start).
- ``hint``: no pose; a coarse position on ``initialpose_hint``: the start position offset by a seeded Gaussian of
  ``--hint-sigma`` metres in x and in y. The localizer's automatic global search starts from it.
- ``none``: neither pose nor hint: the automatic global search covers the whole loaded map.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

START_MODES = ("pose", "hint", "none")


def offset_pose(pose: Sequence[float], distance_m: float, yaw_deg: float, seed: int) -> list[float]:
    """``pose`` (x y z roll pitch yaw [m, rad]) moved by ``distance_m`` in the x-y plane, in a direction drawn
    uniformly from the circle by a generator seeded with ``seed``, and its yaw turned by ``yaw_deg`` (wrapped to
    (-pi, pi])."""
    x, y, z, roll, pitch, yaw = (float(v) for v in pose)
    direction = np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi)
    turned = yaw + math.radians(yaw_deg)
    turned = math.atan2(math.sin(turned), math.cos(turned))
    return [x + distance_m * math.cos(direction), y + distance_m * math.sin(direction), z, roll, pitch, turned]


def sample_hint(xy: Sequence[float], sigma_m: float, seed: int) -> tuple[float, float]:
    """A coarse position near ``xy`` [m]: each coordinate offset by a normal draw of standard deviation
    ``sigma_m``, from a generator seeded with ``seed``."""
    dx, dy = np.random.default_rng(seed).normal(0.0, sigma_m, 2)
    return float(xy[0] + dx), float(xy[1] + dy)


@dataclass(frozen=True)
class StartSetting:
    """The experiment's start options."""

    mode: str = "pose"  # START_MODES
    hint_sigma_m: float = 20.0  # hint: standard deviation of the position's offset in x and in y [m]
    offset_m: float = 0.0  # pose: distance the start pose is moved [m]
    offset_deg: float = 0.0  # pose: angle its yaw is turned [deg]
    seed: int = 0  # of the offset's direction and of the hint's draw


@dataclass(frozen=True)
class Start:
    """What the localizer is given: an initial pose (x y z roll pitch yaw [m, rad]) or a hint (x, y [m] with its
    standard deviation), or neither."""

    mode: str
    initial_pose: list[float] | None
    hint_xy: tuple[float, float] | None = None
    hint_sigma_m: float | None = None

    def as_dict(self) -> dict:
        return {
            "mode": self.mode,
            "initial_pose": self.initial_pose,
            "hint_xy": None if self.hint_xy is None else list(self.hint_xy),
            "hint_sigma_m": self.hint_sigma_m,
        }


def start_from(setting: StartSetting, start_pose: Sequence[float] | None) -> Start:
    """What the localizer is given for ``setting``, ``start_pose`` (x y z roll pitch yaw) being where the run
    really starts (None only for the start ``none``, which needs none)."""
    if setting.mode == "pose":
        pose = [float(v) for v in start_pose]
        if setting.offset_m or setting.offset_deg:
            pose = offset_pose(pose, setting.offset_m, setting.offset_deg, setting.seed)
        return Start("pose", pose)
    if setting.mode == "hint":
        hint = sample_hint(start_pose[:2], setting.hint_sigma_m, setting.seed)
        return Start("hint", None, hint, setting.hint_sigma_m)
    if setting.mode == "none":
        return Start("none", None)
    raise ValueError(f"unknown start mode {setting.mode!r} (use {', '.join(START_MODES)})")
