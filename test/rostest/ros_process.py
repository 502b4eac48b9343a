"""Process ids of running ROS nodes, for tests that kill them."""

from __future__ import annotations

import time
import xmlrpc.client

import rosgraph
import rosnode


def node_pid(name: str, caller: str, wait: float, other_than: int | None = None) -> int:
    """The pid of node ``name`` as the master knows it, asked as ``caller``; with ``other_than``, waits until a
    process with another pid has registered (the master keeps a killed node's URI until its successor
    registers). Raises AssertionError after ``wait`` seconds."""
    deadline = time.monotonic() + wait
    while True:
        try:
            uri = rosnode.get_api_uri(rosgraph.Master(caller), name, skip_cache=True)
            code, _, pid = xmlrpc.client.ServerProxy(uri).getPid(caller)
            if code == 1 and pid != other_than:
                return pid
        except (OSError, TypeError):  # the URI of the killed process; none registered yet
            pass
        if time.monotonic() > deadline:
            raise AssertionError(f"no process other than {other_than} registered as {name} within {wait} s")
        time.sleep(0.2)
