"""`check_network`: the ROS graph across machines checked from this machine, in words, one line per
finding (``ok:``, ``warning:``, ``error:``), exit 1 when anything is an error (doc/network.md).

    rosrun vr_driver check_network                      on the workstation, before its nodes
    rosrun vr_driver check_network --remote-clients     on the driver PC: nodes elsewhere will connect here

It checks (:mod:`vr_driver.ros.network_check`): the master at ROS_MASTER_URI answers; the host this
machine's nodes advertise (ROS_HOSTNAME, ROS_IP or the host name) resolves to an address of this
machine the master's side can reach (else it names the ROS_IP to set); every node registered with the
master is reachable from here by the URI it advertises; ``/use_sim_time`` is false or unset; and,
with the master on another machine, this clock against the driver's (the stamps of
``joint_states``). ``driver_pc.launch`` and ``workstation.launch`` run it at their start.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from typing import List, Optional

from .network_check import (ERROR, OK, Machine, Verdict, advertised_host, check_clock, check_master, check_nodes,
                            check_own_host, check_sim_time, is_loopback)

EXIT_OK, EXIT_PROBLEM = 0, 1
#: [s] how long to wait for a stamped message of the driver's to compare the clocks
CLOCK_WAIT = 5.0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="check_network", description=__doc__.split("\n\n")[0])
    parser.add_argument("--remote-clients", action="store_true",
                        help="this machine runs the master and the driver, nodes on other machines will "
                             "connect to them: a host name that only this machine can resolve is an error")
    parser.add_argument("--timeout", type=float, default=2.0, help="s a TCP connection may take (default 2)")
    parser.add_argument("--clock-topic", default="joint_states",
                        help="the driver's sensor_msgs/JointState topic, whose stamps the clocks are compared by "
                             "(default joint_states)")
    parser.add_argument("--no-nodes", action="store_true", help="do not try the registered nodes' URIs")
    return parser


def graph_verdicts(machine: Machine, master_address: str, timeout: float, with_nodes: bool) -> List[Verdict]:
    """/use_sim_time and the nodes' URIs, from the master's answers (rosgraph, no node of our own)."""
    import rosgraph
    master = rosgraph.Master("/check_network")
    try:
        use_sim_time = master.getParam("/use_sim_time") if master.hasParam("/use_sim_time") else None
        publishers, subscribers, services = master.getSystemState()
    except Exception as exc:  # the master's XML-RPC failed after its port answered: say so, check no more
        return [Verdict(ERROR, "the master answered, but not as a ROS master: %s" % exc)]
    clock = next((nodes for topic, nodes in publishers if topic == "/clock"), [])
    verdicts = [check_sim_time(use_sim_time, clock)]
    if with_nodes:
        names = sorted({n for _topic, nodes in publishers + subscribers + services for n in nodes})
        uris = {}
        for name in names:
            try:
                uris[name] = master.lookupNode(name)
            except Exception:  # gone meanwhile
                continue
        verdicts += check_nodes(uris, machine, timeout)
    return verdicts


def clock_offset(topic: str, wait: float, samples: int = 10) -> Optional[float]:
    """This clock minus the stamps of sensor_msgs/JointState messages of ``topic``: the least over
    ``samples`` of them (the one that waited least on the way), or None when none came within
    ``wait`` s."""
    import threading

    import rospy
    from sensor_msgs.msg import JointState
    from .support import init_node
    init_node("check_network", anonymous=True, disable_signals=True)
    offsets: List[float] = []
    enough = threading.Event()

    def seen(msg) -> None:
        offsets.append(time.time() - msg.header.stamp.to_sec())
        if len(offsets) >= samples:
            enough.set()
    sub = rospy.Subscriber(topic, JointState, seen, queue_size=samples)
    enough.wait(wait)
    sub.unregister()
    return min(offsets) if offsets else None


def run(args: argparse.Namespace, machine: Machine, say=print) -> int:
    uri = os.environ.get("ROS_MASTER_URI")
    master, address = check_master(uri, machine, args.timeout)
    host, source = advertised_host()
    verdicts = [master, check_own_host(host, source, address, machine, args.remote_clients)]
    if master.level == OK:
        verdicts += graph_verdicts(machine, address, args.timeout, not args.no_nodes)
        if not (is_loopback(address) or machine.is_own(address)):
            verdicts.append(check_clock(clock_offset(args.clock_topic, CLOCK_WAIT), args.clock_topic))
    for verdict in verdicts:
        say(verdict.line())
    errors = sum(v.level == ERROR for v in verdicts)
    if errors:
        say("check_network: %d error%s: the ROS graph across machines will not work as it is "
            "(doc/network.md of vr_driver)" % (errors, "" if errors == 1 else "s"))
        return EXIT_PROBLEM
    return EXIT_OK


def main(argv: Optional[List[str]] = None) -> int:
    if argv is None:
        try:
            import rospy
            argv = rospy.myargv(sys.argv)[1:]
        except ImportError:
            argv = sys.argv[1:]
    args = build_parser().parse_args(argv)
    try:
        return run(args, Machine(), say=lambda text: print(text, flush=True))
    finally:
        try:
            import rospy
            if rospy.core.is_initialized():
                rospy.signal_shutdown("check_network done")
        except ImportError:
            pass


__all__ = ["main", "run", "build_parser", "EXIT_OK", "EXIT_PROBLEM"]
