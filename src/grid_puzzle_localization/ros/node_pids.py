"""PIDs of ROS nodes by name, through the ROS master (lookupNode) and the node's own XML-RPC API
(getPid). Used by the resource monitor to follow nodes, including respawned ones."""

from __future__ import annotations

import http.client
import xmlrpc.client

import rosgraph

from grid_puzzle_localization.monitor.sampler import Target

CALLER_ID = "/gpm_monitor"


class _TimeoutTransport(xmlrpc.client.Transport):
    """XML-RPC over HTTP with a socket timeout, so a hung node cannot stall the monitor."""

    def __init__(self, timeout_s: float):
        super().__init__()
        self.timeout_s = timeout_s

    def make_connection(self, host):
        conn = super().make_connection(host)
        conn.timeout = self.timeout_s
        return conn


def node_pid(name: str, master_uri: str | None = None, timeout_s: float = 2.0) -> int | None:
    """PID of the node registered as ``name`` (e.g. ``/ndt_localizer``), or None when the master does
    not know it or the node does not answer. ``master_uri`` defaults to ROS_MASTER_URI."""
    master = rosgraph.Master(CALLER_ID, master_uri=master_uri)
    try:
        uri = master.lookupNode(rosgraph.names.script_resolve_name(CALLER_ID, name))
    except (rosgraph.MasterError, OSError):
        return None
    try:
        code, _msg, pid = xmlrpc.client.ServerProxy(uri, transport=_TimeoutTransport(timeout_s)).getPid(CALLER_ID)
    except (OSError, xmlrpc.client.Error, http.client.HTTPException):
        return None
    return int(pid) if code == 1 else None


def node_target(name: str, master_uri: str | None = None) -> Target:
    """A monitor target that follows the node ``name`` across respawns."""
    return Target(name, lambda: node_pid(name, master_uri), respawns=True)
