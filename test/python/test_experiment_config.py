"""gpm experiment's inputs: scenario directories, presets and bad input, each with its message."""

import dataclasses

import pytest

from grid_puzzle_localization.cli import build_parser, main
from grid_puzzle_localization.commands.experiment import config_from_args
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.experiment.modes import EMPTY_MAP_MODES
from grid_puzzle_localization.experiment.runner import launch_args, mode_roles, required_nodes
from grid_puzzle_localization.experiment.scenario import read_scenario


def scenario_dir(tmp_path, bags=("scenario.bag",), gt=True):
    for b in bags:
        (tmp_path / b).write_bytes(b"")
    (tmp_path / "global_map.pcd").write_bytes(b"")
    if gt:
        (tmp_path / "ground_truth.tum").write_text("1.0 0 0 0 0 0 0 1\n")
    (tmp_path / "scenario.yaml").write_text("parameters:\n  world: courtyard\n  seed: 3\n")
    return tmp_path


def test_scenario_directory_is_read(tmp_path):
    s = read_scenario(scenario_dir(tmp_path))
    assert (s.name, s.bag.name, s.global_map.name, s.ground_truth.name) == (
        "courtyard",
        "scenario.bag",
        "global_map.pcd",
        "ground_truth.tum",
    )


@pytest.mark.parametrize(
    ("bags", "message"),
    [((), "exactly one .bag"), (("a.bag", "b.bag"), r"exactly one \.bag file \(found \['a.bag', 'b.bag'\]")],
)
def test_scenario_needs_exactly_one_bag(tmp_path, bags, message):
    with pytest.raises(UserError, match=message):
        read_scenario(scenario_dir(tmp_path, bags))


def test_presets_and_overrides(tmp_path):
    d = scenario_dir(tmp_path)
    args = build_parser().parse_args(["experiment", str(d), "-o", "out", "--preset", "urban", "--k", "7"])
    cfg = config_from_args(args)
    assert (cfg.window.n, cfg.window.k, cfg.window.grid_size_m) == (25, 7, 2.0)
    assert cfg.modes == ["global", "grid_puzzle", "grid_puzzle_rospy"] and cfg.scenario_name == "courtyard"
    cfg.check()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["-o", "out"], "give a scenario directory, or --bag and --map"),
        (["/nonexistent_scenario", "-o", "out"], "does not exist"),
        (
            ["--bag", "/nonexistent.bag", "--map", "/nonexistent.pcd", "-o", "out"],
            "bag /nonexistent.bag does not exist",
        ),
        (["SCN", "-o", "out", "--rate", "0"], "--rate must be > 0"),
        (["SCN", "-o", "out", "--repeats", "0"], "--repeats must be >= 1"),
        (["SCN", "-o", "out", "--modes", "block_map", "--block-size", "0"], "--block-size must be > 0"),
    ],
)
def test_bad_input_is_a_user_error(tmp_path, capsys, argv, message):
    d = scenario_dir(tmp_path)
    assert main(["experiment", *[str(d) if a == "SCN" else a for a in argv]]) == 2
    assert message in capsys.readouterr().err


def test_block_map_without_blocks_needs_ground_truth(tmp_path, capsys):
    d = scenario_dir(tmp_path, gt=False)
    argv = ["experiment", str(d), "-o", str(tmp_path / "out"), "--modes", "block_map", "--initial-pose", *"000000"]
    assert main(argv) == 2
    assert "needs --blocks" in capsys.readouterr().err


def test_without_ground_truth_an_initial_pose_is_needed(tmp_path, capsys):
    d = scenario_dir(tmp_path, gt=False)
    assert main(["experiment", str(d), "-o", str(tmp_path / "out")]) == 2
    assert "--initial-pose" in capsys.readouterr().err


def test_fusion_reaches_the_localizer_launch(tmp_path):
    d = scenario_dir(tmp_path)
    cfg = config_from_args(build_parser().parse_args(["experiment", str(d), "-o", "out", "--fusion", "sliding_window"]))
    cfg.check()
    assert launch_args(cfg, "global", cfg.global_map, None, [0.0] * 6)["fusion"] == "sliding_window"
    default = config_from_args(build_parser().parse_args(["experiment", str(d), "-o", "out"]))
    assert default.fusion is None and "fusion" not in launch_args(
        default, "global", default.global_map, None, [0.0] * 6
    )


def test_unknown_fusion_is_refused(tmp_path):
    cfg = config_from_args(build_parser().parse_args(["experiment", str(scenario_dir(tmp_path)), "-o", "out"]))
    with pytest.raises(UserError, match="unknown fusion 'ukf' \\(use none, sliding_window, auto\\)"):
        dataclasses.replace(cfg, fusion="ukf").check()


def test_grid_puzzle_runs_the_provider_nodelet_and_grid_puzzle_rospy_the_papers_rospy_provider(tmp_path):
    d = scenario_dir(tmp_path)
    cfg = config_from_args(build_parser().parse_args(["experiment", str(d), "-o", "out"]))
    tiles = tmp_path / "tiles"
    args = {mode: launch_args(cfg, mode, cfg.global_map, tiles, [0.0] * 6) for mode in cfg.modes}
    assert (args["grid_puzzle"]["mode"], args["grid_puzzle"]["provider"]) == ("grid_puzzle", "nodelet")
    assert (args["grid_puzzle_rospy"]["mode"], args["grid_puzzle_rospy"]["provider"]) == ("grid_puzzle", "rospy")
    assert args["grid_puzzle"]["tiles"] == args["grid_puzzle_rospy"]["tiles"] == tiles.resolve()
    assert args["global"]["mode"] == "global" and "provider" not in args["global"]
    # The nodelet's process is the localizer's manager; the rospy provider is a process of its own.
    assert mode_roles(cfg, "grid_puzzle") == {"localizer": "/localizer_manager", "map_provider": "/localizer_manager"}
    assert mode_roles(cfg, "grid_puzzle_rospy") == {
        "localizer": "/localizer_manager",
        "map_provider": "/grid_puzzle_map_provider",
    }
    # The runner waits for the rospy provider's node; the nodelet has none (it is in the localizer's process).
    assert required_nodes(cfg, "grid_puzzle") == {"/localizer_manager"}
    assert required_nodes(cfg, "grid_puzzle_rospy") == {"/localizer_manager", "/grid_puzzle_map_provider"}
    assert required_nodes(cfg, "global") == {"/localizer_manager"}
    assert set(EMPTY_MAP_MODES) == {"global", "grid_puzzle", "grid_puzzle_rospy"}
