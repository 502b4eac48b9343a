"""The ROS side of the experiment, as child processes: a roscore on a free port (never 11311, so
runs and tests can go in parallel), roslaunch, rosbag play; and read-only queries of the master."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import rosgraph
import roslib.packages

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.experiment.processes import ManagedProcess, free_port, wait_for

CALLER_ID = "/gpm_experiment"
PACKAGE = "grid_puzzle_localization"


def ros_environment(port: int, log_dir: str | os.PathLike) -> dict[str, str]:
    """This process's environment pointed at a master on ``port`` of the loopback interface, with
    ROS logs under ``log_dir``. The paths are absolute: roslaunch starts nodes in ROS_HOME, where a
    relative log directory would nest."""
    log_dir = Path(log_dir).resolve()
    env = dict(os.environ)
    env.update(
        ROS_MASTER_URI=f"http://127.0.0.1:{port}",
        ROS_IP="127.0.0.1",
        ROS_HOME=str(log_dir / "ros_home"),
        ROS_LOG_DIR=str(log_dir / "ros_log"),
    )
    env.pop("ROS_HOSTNAME", None)
    return env


def master_is_up(master_uri: str) -> bool:
    try:
        rosgraph.Master(CALLER_ID, master_uri=master_uri).getPid()
    except Exception:  # any failure means "not yet"
        return False
    return True


class RosCore:
    """roscore on a free port; ``env`` is the environment children must use."""

    def __init__(self, log_dir: str | os.PathLike, timeout_s: float = 30.0):
        self.port = free_port()
        self.env = ros_environment(self.port, log_dir)
        self.master_uri = self.env["ROS_MASTER_URI"]
        self.process = ManagedProcess(
            "roscore", ["roscore", "-p", str(self.port)], self.env, Path(log_dir) / "roscore.log"
        )
        try:
            wait_for(lambda: master_is_up(self.master_uri), timeout_s, f"roscore on port {self.port}", self.process)
            wait_for(lambda: "/rosout" in self.nodes(), timeout_s, "the /rosout node", self.process)
        except BaseException:
            self.process.stop()
            raise

    def _system_state(self) -> tuple[list, list, list]:
        """(publishers, subscribers, services) as the master lists them; empty when it does not answer."""
        try:
            return rosgraph.Master(CALLER_ID, master_uri=self.master_uri).getSystemState()
        except Exception:
            return [], [], []

    def nodes(self) -> set[str]:
        """Names of the nodes the master knows (publishers, subscribers or service providers)."""
        return {node for section in self._system_state() for _name, nodes in section for node in nodes}

    def subscribers(self, topic: str) -> set[str]:
        return {node for t, nodes in self._system_state()[1] if t == topic for node in nodes}

    def stop(self) -> list[int]:
        return self.process.stop()

    def __enter__(self) -> RosCore:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def roslaunch(
    launch_file: str, args: Mapping[str, object], env: Mapping[str, str], log_path: str | os.PathLike
) -> ManagedProcess:
    """``roslaunch grid_puzzle_localization <launch_file> name:=value ...`` (or an absolute launch file
    path) against the master in ``env``; nodes get 5 s to exit on SIGINT, then 2 s on SIGTERM."""
    where = [launch_file] if os.path.isabs(launch_file) else [PACKAGE, launch_file]
    argv = ["roslaunch", "--sigint-timeout", "5", "--sigterm-timeout", "2", *where]
    argv += [f"{k}:={v}" for k, v in args.items()]
    return ManagedProcess("roslaunch", argv, env, log_path)


def run_node(
    name: str, executable: str, argv: Sequence[str], env: Mapping[str, str], log_path: str | os.PathLike
) -> ManagedProcess:
    """A node executable of this package, found as roslaunch finds it (the devel-space relay first), so
    the PID is the node's. (rosrun would stop to ask when the package holds its own workspace.)"""
    matches = roslib.packages.find_node(PACKAGE, executable)
    if not matches:
        raise UserError(f"cannot find the node executable {executable} of {PACKAGE}; build with `make build`")
    return ManagedProcess(name, [matches[0], *argv], env, log_path)


def rosbag_play(
    bag: str | os.PathLike,
    rate: float,
    env: Mapping[str, str],
    log_path: str | os.PathLike,
    delay_s: float = 1.0,
    duration_s: float | None = None,
) -> ManagedProcess:
    """``rosbag play --clock`` at ``rate`` times real time, after ``delay_s`` for subscribers to connect;
    the first ``duration_s`` seconds of the bag only, when given."""
    argv = ["rosbag", "play", "--clock", "--quiet", "-r", str(rate), "-d", str(delay_s)]
    if duration_s is not None:
        argv += ["-u", str(duration_s)]
    argv.append(str(bag))
    return ManagedProcess("rosbag play", argv, env, log_path)
