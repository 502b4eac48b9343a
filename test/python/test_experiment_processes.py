"""The experiment's process handling: shutdown escalation with no stray processes, roscore on a free
port, node PIDs through the master, and TUM recording of an Odometry topic played from a bag."""

import subprocess
import sys
import time

import numpy as np
import psutil
import pytest
import rosbag
import rospy
from nav_msgs.msg import Odometry

from grid_puzzle_localization.cli import main
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.experiment.processes import ManagedProcess, free_port, wait_for
from grid_puzzle_localization.experiment.ros_stack import RosCore, rosbag_play, run_node
from grid_puzzle_localization.ros.node_pids import node_pid

# Prints "ready" once its signal handlers are set; ignores the signals named in argv.
STUBBORN = """
import signal, sys, time
for name in sys.argv[1:]:
    signal.signal(getattr(signal, name), signal.SIG_IGN)
print("ready", flush=True)
while True:
    time.sleep(0.1)
"""

# Starts a grandchild in a session of its own (as roslaunch starts nodes) that ignores SIGINT and
# SIGTERM, prints its PID, then waits to be interrupted.
PARENT = """
import subprocess, sys, time
child = subprocess.Popen([sys.executable, "-c", sys.argv[1], "SIGINT", "SIGTERM"], stdout=subprocess.PIPE,
                         start_new_session=True)
child.stdout.readline()
print(child.pid, flush=True)
time.sleep(1000)
"""


def start(tmp_path, *ignored: str) -> ManagedProcess:
    proc = ManagedProcess("stubborn", [sys.executable, "-c", STUBBORN, *ignored], {}, tmp_path / "p.log")
    wait_for(lambda: "ready" in (tmp_path / "p.log").read_text(), 10, "the child to start", proc)
    return proc


def gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def test_stop_with_sigint(tmp_path):
    proc = start(tmp_path)
    assert proc.stop(sigint_timeout_s=5, sigterm_timeout_s=1) == []
    assert proc.popen.returncode != 0 and gone(proc.pid)


def test_stop_escalates_to_sigterm(tmp_path):
    proc = start(tmp_path, "SIGINT")
    assert proc.stop(sigint_timeout_s=0.5, sigterm_timeout_s=5) == []
    assert proc.popen.returncode == -15


def test_stop_escalates_to_sigkill(tmp_path):
    proc = start(tmp_path, "SIGINT", "SIGTERM")
    assert proc.stop(sigint_timeout_s=0.5, sigterm_timeout_s=0.5) == [proc.pid]
    assert proc.popen.returncode == -9


def test_grandchild_in_its_own_session_is_not_left_behind(tmp_path):
    proc = ManagedProcess("parent", [sys.executable, "-c", PARENT, STUBBORN], {}, tmp_path / "p.log")
    text = wait_for(lambda: (tmp_path / "p.log").read_text().strip(), 10, "the grandchild", proc)
    grandchild = int(text.split()[0])
    assert psutil.Process(grandchild).ppid() == proc.pid
    proc.remember_descendants()
    killed = proc.stop(sigint_timeout_s=1, sigterm_timeout_s=0.5)
    assert killed == [grandchild]
    assert gone(grandchild) and gone(proc.pid) and proc.alive_pids() == []


def test_missing_program_is_a_user_error(tmp_path):
    with pytest.raises(Exception, match="cannot start nothing"):
        ManagedProcess("nothing", ["/nonexistent/program"], {}, tmp_path / "n.log")


def test_free_port_is_bindable():
    port = free_port()
    assert port != 11311
    subprocess.run([sys.executable, "-c", f"import socket; socket.create_server(('127.0.0.1', {port}))"], check=True)


@pytest.fixture
def roscore(tmp_path):
    core = RosCore(tmp_path / "core")
    yield core
    core.stop()
    assert core.process.alive_pids() == []


def test_roscore_runs_on_its_own_port_and_stops_cleanly(tmp_path, roscore):
    assert roscore.port != 11311 and roscore.master_uri == f"http://127.0.0.1:{roscore.port}"
    assert "/rosout" in roscore.nodes()
    with RosCore(tmp_path / "second") as second:  # two at once, as parallel tests need
        assert second.port != roscore.port and "/rosout" in second.nodes()
    pids = roscore.process.remember_descendants()
    assert len(pids) >= 2  # roscore and rosmaster (and rosout)
    assert roscore.stop() == []
    assert all(gone(p.pid) for p in pids)


def test_a_relative_log_dir_keeps_every_ros_log_in_it(tmp_path, monkeypatch):
    # roslaunch starts rosout in ROS_HOME; a relative ROS_LOG_DIR used to land under ros_home/ again.
    monkeypatch.chdir(tmp_path)
    with RosCore("relative/logs"):
        pass
    logs = sorted(p.name for p in (tmp_path / "relative" / "logs" / "ros_log").rglob("*.log"))
    assert "master.log" in logs and "rosout.log" in logs
    assert not list((tmp_path / "relative" / "logs" / "ros_home").rglob("*.log"))


def write_odometry_bag(path, n: int = 40) -> np.ndarray:
    """A bag of Odometry on `odom` at 10 Hz along a known curve; returns the rows t x y z qx qy qz qw."""
    rows = []
    with rosbag.Bag(str(path), "w") as bag:
        for i in range(n):
            t = 1000.0 + 0.1 * i
            yaw = 0.05 * i
            msg = Odometry()
            msg.header.stamp = rospy.Time.from_sec(t)
            msg.header.frame_id = "map"
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            p.x, p.y, p.z = 3.0 * np.cos(yaw), 3.0 * np.sin(yaw), 0.01 * i
            q.z, q.w = np.sin(yaw / 2), np.cos(yaw / 2)
            bag.write("odom", msg, msg.header.stamp)
            rows.append([msg.header.stamp.to_sec(), p.x, p.y, p.z, 0.0, 0.0, q.z, q.w])
    return np.array(rows)


def test_recorder_writes_the_played_odometry_as_tum(tmp_path, roscore, monkeypatch, capsys):
    expected = write_odometry_bag(tmp_path / "odom.bag")
    out = tmp_path / "traj.tum"
    recorder = run_node(
        "recorder",
        "trajectory_recorder",
        [f"_output:={out}", "_initial_pose:=[1.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0]"],
        roscore.env,
        tmp_path / "rec.log",
    )
    try:
        wait_for(lambda: "/trajectory_recorder" in roscore.subscribers("/odom"), 30, "the recorder", recorder)
        assert node_pid("/trajectory_recorder", roscore.master_uri) == recorder.pid
        assert node_pid("/no_such_node", roscore.master_uri) is None
        # gpm monitor resolves the node by name through ROS_MASTER_URI.
        monkeypatch.setenv("ROS_MASTER_URI", roscore.master_uri)
        assert main(["monitor", "/trajectory_recorder", "--interval", "0.2", "--duration", "0.6"]) == 0
        assert f'"pids": [\n        {recorder.pid}\n      ]' in capsys.readouterr().out
        player = rosbag_play(tmp_path / "odom.bag", 4.0, roscore.env, tmp_path / "play.log", delay_s=0.5)
        assert player.wait(60) == 0
        time.sleep(1.0)  # let the last messages arrive
    finally:
        assert recorder.stop() == []
    traj = read_tum(out)
    np.testing.assert_allclose(traj.t, expected[:, 0], atol=1e-9)
    np.testing.assert_allclose(traj.xyz, expected[:, 1:4], atol=1e-9)
    np.testing.assert_allclose(traj.quat, expected[:, 4:8], atol=1e-9)
