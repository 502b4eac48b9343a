"""config/ndt_localizer.yaml documents the localizer nodelet's ROS-only defaults exactly as the C++ structs set them
(LocalizerRosParams and GlobalLocalizationParams in src/nodelets/localizer_params.hpp): the YAML sets nothing, each
line is the struct's default, commented out."""

from __future__ import annotations

import math
import re
from pathlib import Path

import yaml
from documented_defaults import documented_defaults

ROOT = Path(__file__).resolve().parents[2]
YAML = ROOT / "config" / "ndt_localizer.yaml"
HEADER = ROOT / "src" / "nodelets" / "localizer_params.hpp"
MAP_UPDATE_WORKER = ROOT / "include" / "grid_puzzle_localization" / "map_update_worker.hpp"

# parameter name -> struct field, for every ROS-only parameter with a default in localizer_params.hpp
FIELDS = {
    "map_source": "map_source",
    "resend_service": "resend_service",
    "tiles/cache_mb": "tile_cache_mb",
    "map_frame": "map_frame",
    "odom_frame": "odom_frame",
    "base_frame": "base_frame",
    "publish_tf": "publish_tf",
    "publish_aligned_points": "publish_aligned_points",
    "save_pose_rate": "save_pose_rate",
    "preprocess/time_field": "time_field",
    "global_localization/auto_start_timeout": "auto_start_timeout",
    "global_localization/size": "size",
    "global_localization/yaw_range": "yaw_range",
}
CONSTANTS = {"M_PI": math.pi}


def struct_defaults() -> dict:
    """``{field: value}`` of the fields with a literal default (``type name = value;``) in the header; a field
    set from MapUpdateWorker::kDefault... takes that constant's value."""
    constants = dict(CONSTANTS)
    for name, value in re.findall(r"constexpr double (k\w+) = ([-0-9.e]+);", MAP_UPDATE_WORKER.read_text()):
        constants[f"MapUpdateWorker::{name}"] = float(value)
    out = {}
    for name, value in re.findall(r"^\s*[\w:]+ (\w+) = ([^;]+);", HEADER.read_text(), re.MULTILINE):
        out[name] = constants[value] if value in constants else yaml.safe_load(value)
    return out


def test_yaml_sets_nothing():
    assert yaml.safe_load(YAML.read_text()) is None  # launch files and YAML override only what a user sets


def test_yaml_documents_the_struct_defaults():
    documented = documented_defaults(YAML.read_text())
    structs = struct_defaults()
    for param, field in FIELDS.items():
        assert param in documented, f"{param} is not documented in {YAML.name}"
        assert field in structs, f"{field} has no default in {HEADER.name}"
        want, got = structs[field], documented[param]
        if isinstance(want, float):
            # the YAML writes pi to 5 decimals
            assert math.isclose(got, want, abs_tol=1e-5), f"{param}: {YAML.name} says {got}, the struct {want}"
        else:
            assert got == want, f"{param}: {YAML.name} says {got!r}, the struct {want!r}"
