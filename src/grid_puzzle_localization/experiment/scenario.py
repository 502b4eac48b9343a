"""Inputs of an experiment from a scenario directory written by `gpm simulate`:
scenario.yaml, one .bag, ground_truth.tum and global_map.pcd."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

from grid_puzzle_localization.errors import UserError


@dataclass(frozen=True)
class ScenarioInputs:
    name: str
    bag: Path
    global_map: Path
    ground_truth: Path | None
    settings: dict


def read_scenario(directory: str | Path) -> ScenarioInputs:
    d = Path(directory)
    if not d.is_dir():
        raise UserError(f"scenario directory {d} does not exist (make one with `gpm simulate`)")
    bags = sorted(d.glob("*.bag"))
    if len(bags) != 1:
        raise UserError(f"scenario {d} must hold exactly one .bag file (found {[b.name for b in bags]})")
    global_map = d / "global_map.pcd"
    if not global_map.is_file():
        raise UserError(f"scenario {d} has no global_map.pcd")
    gt = d / "ground_truth.tum"
    settings = {}
    if (d / "scenario.yaml").is_file():
        try:
            settings = yaml.safe_load((d / "scenario.yaml").read_text()) or {}
        except yaml.YAMLError as err:
            raise UserError(f"{d / 'scenario.yaml'} is not valid YAML ({err})") from err
    parameters = settings.get("parameters") or {}
    name = str(parameters.get("world") or settings.get("world") or d.name)
    return ScenarioInputs(name, bags[0], global_map, gt if gt.is_file() else None, settings)
