"""The driver's side of the ROS graph across machines (doc/network.md): a node that sends the driver
goals or commands (it publishes a topic the driver subscribes to: an action's ``goal`` and
``cancel``, ``joint_command``, ``joint_path_command``) must be reachable by the URI it advertises,
or nothing it sends ever arrives, and neither side says so -- the classic ROS 1 pitfall of a
workstation without ROS_IP. :class:`SenderWatch` asks the master every few seconds who publishes to
this node, tries each new sender's URI once (:func:`~vr_driver.ros.network_check.check_nodes`) and
logs an error naming the node and what to set on its machine, once per node URI.
"""
from __future__ import annotations

import threading
from typing import Callable, Dict, List, Optional

from .network_check import ERROR, Machine, check_nodes

#: [s] between two looks at the master's list of publishers
PERIOD = 3.0
#: [s] a connection to a sender's URI may take
TIMEOUT = 1.0


class SenderWatch:
    """Watches the publishers of the topics ``node`` (this node's name) subscribes to.
    ``master``: a rosgraph.Master (None: one for ``node``); ``log(text)``: where an unreachable
    sender is reported (rospy.logerr by default)."""

    def __init__(self, node: str, master=None, machine: Optional[Machine] = None,
                 log: Optional[Callable[[str], None]] = None, period: float = PERIOD) -> None:
        if master is None:
            import rosgraph
            master = rosgraph.Master(node)
        if log is None:
            import rospy
            log = lambda text: rospy.logerr("%s", text)  # noqa: E731
        self.node, self.master, self.machine, self.log = node, master, machine or Machine(), log
        self.period = period
        self.checked: Dict[str, str] = {}          # sender -> the URI it was checked at
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None

    def poll(self) -> List[str]:
        """One look: the errors about senders not checked before (also logged)."""
        publishers, subscribers, _services = self.master.getSystemState()
        mine = {topic for topic, nodes in subscribers if self.node in nodes}
        senders: Dict[str, List[str]] = {}
        for topic, nodes in publishers:
            if topic in mine:
                for sender in nodes:
                    if sender != self.node:
                        senders.setdefault(sender, []).append(topic)
        said = []
        for sender, topics in sorted(senders.items()):
            try:
                uri = self.master.lookupNode(sender)
            except Exception:  # gone meanwhile
                continue
            if self.checked.get(sender) == uri:
                continue
            self.checked[sender] = uri
            for verdict in check_nodes({sender: uri}, self.machine, TIMEOUT):
                if verdict.level == ERROR:
                    text = "%s: nothing %s publishes to it (%s) arrives: %s (doc/network.md)" % (
                        self.node, sender, ", ".join(sorted(topics)), verdict.text)
                    self.log(text)
                    said.append(text)
        return said

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            try:
                self.poll()
            except Exception:  # the master away for a moment: look again next time
                continue

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="sender_watch", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()


__all__ = ["SenderWatch", "PERIOD"]
