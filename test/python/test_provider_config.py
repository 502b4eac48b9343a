"""The provider's parameters: the YAML documents exactly the dataclass defaults; loading and checking."""

import json
import subprocess
from pathlib import Path

import pytest
import yaml
from documented_defaults import documented_defaults

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.provider.config import ProviderConfig, load_config, parameter_defaults

YAML = Path(__file__).resolve().parents[2] / "config" / "grid_puzzle_map_provider.yaml"


def test_yaml_documents_every_parameter_with_its_default_and_sets_none():
    text = YAML.read_text()
    assert yaml.safe_load(text) is None  # launch files and YAML override only what a user sets
    assert documented_defaults(text) == parameter_defaults()


def test_the_nodelet_has_the_same_parameters_and_defaults():
    from test_window_server_equality import replay_program

    out = subprocess.run([str(replay_program()), "--defaults"], capture_output=True, text=True, check=True).stdout
    assert json.loads(out) == parameter_defaults()


def test_load_config_reads_groups_and_converts_types():
    given = {"tiles/dir": "/maps/t", "window/n": 17, "tiles/grid_size": 2, "publish_map_cloud": True}
    cfg = load_config(lambda name, default: given.get(name, default))
    assert cfg.tiles.dir == "/maps/t" and cfg.window.n == 17 and cfg.tiles.grid_size == 2.0
    assert isinstance(cfg.tiles.grid_size, float) and cfg.publish_map_cloud is True
    assert cfg.checked().window.k == 20


@pytest.mark.parametrize(
    ("given", "match"),
    [
        ({"window/n": "many"}, "window/n must be a int"),
        ({"publish_map_cloud": 1}, "publish_map_cloud must be a bool"),
    ],
)
def test_wrong_types_name_the_parameter(given, match):
    with pytest.raises(UserError, match=match):
        load_config(lambda name, default: given.get(name, default))


@pytest.mark.parametrize(
    ("config", "match"),
    [
        (ProviderConfig(), "tiles/dir is empty"),
        (ProviderConfig(pose_source="gps", tiles=ProviderConfig().tiles.__class__(dir="x")), "pose_source"),
        (ProviderConfig(tiles=ProviderConfig().tiles.__class__(dir="x", grid_size=-1.0)), "grid_size"),
        (ProviderConfig(tiles=ProviderConfig().tiles.__class__(dir="x"), map_cloud_period=-0.5), "map_cloud_period"),
    ],
)
def test_checked_rejects_bad_values(config, match):
    with pytest.raises(UserError, match=match):
        config.checked()
