"""vr_driver.ros.network_check without ROS and without a network: each check against a machine of
the test's own (FakeMachine: what names resolve to, which connections open, which addresses are
this machine's), every verdict and the words that say what to set; and the real Machine on
loopback only. The graph across two network namespaces, end to end: test_two_machines.py."""
from __future__ import annotations

import socket

import pytest

from vr_driver.ros.network_check import (ERROR, OK, WARNING, Machine, check_clock, check_master, check_nodes,
                                         check_own_host, check_sim_time, master_address)

WORKSTATION, DRIVER_PC = "192.168.7.20", "192.168.7.10"


class FakeMachine(Machine):
    """``names``: host -> addresses (missing: does not resolve); ``listening``: (address, port) ->
    None (open) or the exception a connection raises (missing: refused); ``own``: this machine's
    addresses; ``routes``: destination -> this machine's source address."""

    def __init__(self, names=None, listening=None, own=(), routes=None):
        self.names = dict(names or {})
        self.listening = dict(listening or {})
        self.own = list(own)
        self.routes = dict(routes or {})

    def hostname(self):
        return "ws"

    def resolve(self, host):
        try:
            return list(self.names[host]) if host not in self.own else [host]
        except KeyError:
            raise socket.gaierror(-2, "Name or service not known") from None

    def connect(self, address, port, timeout):
        exc = self.listening.get((address, port), ConnectionRefusedError(111, "Connection refused"))
        if exc is not None:
            raise exc

    def route_source(self, address):
        return self.routes.get(address)

    def is_own(self, address):
        return address in self.own or address.startswith("127.")

    def own_addresses(self):
        return [a for a in self.own if not a.startswith("127.")]


def workstation(**names):
    """The workstation: its own address, a route to the driver PC, the master listening there."""
    known = {"driver-pc": [DRIVER_PC], "ws": ["127.0.1.1"], "localhost": ["127.0.0.1"]}
    known.update(names)
    return FakeMachine(names=known, listening={(DRIVER_PC, 11311): None}, own=[WORKSTATION],
                       routes={DRIVER_PC: WORKSTATION})


# ---------------------------------------------------------------------------------------- the master
@pytest.mark.parametrize("uri, words", [
    (None, "ROS_MASTER_URI is not set"),
    ("", "ROS_MASTER_URI is not set"),
    ("192.168.7.10:11311", "is not a master URI: the form is http://HOST:PORT"),
    ("http://192.168.7.10", "is not a master URI"),
    ("http://192.168.7.10:port", "is not a master URI")])
def test_a_master_uri_that_is_not_one_is_named(uri, words):
    where, verdict = master_address(uri)
    assert where is None and verdict.level == ERROR and words in verdict.text


def test_the_master_answering_is_ok():
    verdict, address = check_master("http://driver-pc:11311", workstation())
    assert (verdict.level, address) == (OK, DRIVER_PC)
    assert verdict.text == "the ROS master at http://driver-pc:11311 answers (192.168.7.10)"


@pytest.mark.parametrize("uri, failure, words", [
    ("http://cell-pc:11311", None, "its host name 'cell-pc' does not resolve on this machine; put the driver "
                                   "PC's address in ROS_MASTER_URI (http://<address>:11311) or the name in /etc/hosts"),
    ("http://driver-pc:11312", None, "(ROS_MASTER_URI; 192.168.7.10): connection refused: nothing listens on port "
                                     "11312 there; is roscore (driver_pc.launch) running on that machine"),
    ("http://driver-pc:11311", socket.timeout("timed out"), "no answer within 2 s: a firewall between the machines "
                                                            "drops it (open TCP port 11311"),
    ("http://driver-pc:11311", OSError(113, "No route to host"), "No route to host: is this machine on the "
                                                                 "master's network")])
def test_a_master_out_of_reach_is_named_with_what_to_check(uri, failure, words):
    machine = workstation()
    if failure is not None:
        machine.listening[(DRIVER_PC, 11311)] = failure
    verdict, _address = check_master(uri, machine)
    assert verdict.level == ERROR and verdict.text.startswith("cannot reach the ROS master at %s" % uri)
    assert words in verdict.text, verdict.text


# ------------------------------------------------------------------------------ this machine's name
UNSET = "the host name; ROS_IP and ROS_HOSTNAME are unset"


def test_a_host_name_on_loopback_with_the_master_elsewhere_names_the_ros_ip_to_set():
    # Debian's /etc/hosts: the host name is 127.0.1.1; the driver PC would connect to itself
    verdict = check_own_host("ws", UNSET, DRIVER_PC, workstation())
    assert verdict.level == ERROR
    assert "advertise 'ws' (%s), which is 127.0.1.1 (loopback)" % UNSET in verdict.text
    assert "set ROS_IP=192.168.7.20 (this machine's address toward the master)" in verdict.text


def test_a_host_name_that_does_not_resolve_names_the_ros_ip_to_set():
    machine = workstation()
    del machine.names["ws"]
    verdict = check_own_host("ws", UNSET, DRIVER_PC, machine)
    assert verdict.level == ERROR and "which does not resolve here" in verdict.text
    assert "set ROS_IP=192.168.7.20" in verdict.text


def test_an_address_of_another_machine_in_ros_ip_is_an_error():
    verdict = check_own_host("192.168.7.99", "ROS_IP", DRIVER_PC, workstation(**{"192.168.7.99": ["192.168.7.99"]}))
    assert verdict.level == ERROR and "not an address of this machine; set ROS_IP=192.168.7.20" in verdict.text


def test_ros_ip_this_machines_address_toward_the_master_is_ok():
    verdict = check_own_host(WORKSTATION, "ROS_IP", DRIVER_PC, workstation())
    assert verdict == (OK, "this machine's nodes advertise '192.168.7.20' (ROS_IP)")


def test_a_resolving_ros_hostname_is_ok_and_asks_the_others_to_resolve_it():
    verdict = check_own_host("ws.cell", "ROS_HOSTNAME", DRIVER_PC, workstation(**{"ws.cell": [WORKSTATION]}))
    assert verdict.level == OK
    assert "'ws.cell' (ROS_HOSTNAME) = 192.168.7.20 here; the other machines must resolve 'ws.cell' to it" \
        in verdict.text


def test_an_own_address_off_the_way_to_the_master_is_a_warning():
    machine = workstation()
    machine.own.append("10.0.0.5")
    verdict = check_own_host("10.0.0.5", "ROS_IP", DRIVER_PC, machine)
    assert verdict.level == WARNING
    assert "it reaches the master from 192.168.7.20: the master's machine must route to 10.0.0.5" in verdict.text


def test_loopback_is_fine_with_the_master_on_this_machine_unless_others_connect():
    machine = FakeMachine(names={"cell-pc": ["127.0.1.1"]}, own=["192.168.7.10", "10.0.0.5"])
    assert check_own_host("cell-pc", UNSET, "127.0.0.1", machine).level == OK
    # driver_pc.launch: the workstation's nodes will connect here
    verdict = check_own_host("cell-pc", UNSET, "127.0.0.1", machine, remote_clients=True)
    assert verdict.level == ERROR
    assert ("set ROS_IP=192.168.7.10 or ROS_IP=10.0.0.5 (this machine's address on the workstations' network, "
            "one of them)") in verdict.text
    assert "nodes on other machines (the workstation) would connect to themselves" in verdict.text


def test_an_unknown_master_and_ipv6_are_not_judged():
    verdict = check_own_host("ws", UNSET, None, workstation())
    assert verdict.level == WARNING and "not checked: the master's address is not known" in verdict.text
    verdict = check_own_host("fd00::20", "ROS_IP", DRIVER_PC, workstation())
    assert verdict.level == WARNING and "an IPv6 address: not checked" in verdict.text


# ------------------------------------------------------------------------------ the other nodes
def test_nodes_out_of_reach_by_their_names_are_each_named():
    machine = workstation(**{"cell-pc": ["127.0.1.1"]})
    machine.listening[(DRIVER_PC, 40001)] = None
    verdicts = check_nodes({"/interface": "http://driver-pc:40001/", "/rosout": "http://cell-pc:40002/",
                            "/probe": "http://nowhere:40003/", "/v6": "http://[fd00::5]:40004/"},
                           machine, timeout=0.1)
    assert [v.level for v in verdicts] == [ERROR, ERROR, OK]
    assert verdicts[0].text.startswith("node /probe advertises http://nowhere:40003/, which this machine cannot "
                                       "reach ('nowhere' does not resolve here): set ROS_IP")
    assert "node /rosout advertises http://cell-pc:40002/, which this machine cannot reach (cell-pc = 127.0.1.1 " \
           "here: connection refused)" in verdicts[1].text
    assert verdicts[2].text == "2 nodes reachable by the URIs they advertise"


# ------------------------------------------------------------------------------ time
def test_the_clock_offset_is_judged_against_what_the_driver_does_with_stamps():
    assert check_clock(None, "joint_states").level == WARNING
    assert check_clock(0.02, "joint_states").level == OK
    ahead = check_clock(0.3, "joint_states")
    assert ahead.level == WARNING and "starts that much late: the driver waits for its stamp" in ahead.text
    behind = check_clock(-0.7, "joint_states")
    assert behind.level == ERROR and "refuses one more than 0.5 s in the past" in behind.text
    assert "synchronise the clocks (chrony" in behind.text


def test_sim_time_is_an_error_for_the_driver():
    assert check_sim_time(None, []).level == OK
    assert check_sim_time(False, []).level == OK
    still = check_sim_time(True, [])
    assert still.level == ERROR and "nobody publishes /clock, so ROS time stands still" in still.text
    assert "/clock is published by /player" in check_sim_time(True, ["/player"]).text


# ------------------------------------------------------------------------------ the real machine, on loopback
def test_the_real_machine_on_loopback():
    machine = Machine()
    assert "127.0.0.1" in machine.resolve("localhost")
    assert machine.is_own("127.0.0.1")
    assert machine.route_source("127.0.0.1") == "127.0.0.1"
    assert not any(a.startswith("127.") for a in machine.own_addresses())
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        port = server.getsockname()[1]
        with pytest.raises(ConnectionRefusedError):       # bound, not listening
            machine.connect("127.0.0.1", port, 1.0)
        server.listen()
        machine.connect("127.0.0.1", port, 1.0)
    verdict, address = check_master("http://localhost:%d" % port, machine)
    assert verdict.level == ERROR and address == "127.0.0.1"


# ------------------------------------------------------------------------------ the driver's side
class FakeMaster:
    def __init__(self, publishers, subscribers, uris):
        self.state = (publishers, subscribers, [])
        self.uris = dict(uris)

    def getSystemState(self):  # noqa: N802 (rosgraph's name)
        return self.state

    def lookupNode(self, name):  # noqa: N802
        return self.uris[name]


def test_the_driver_names_a_sender_it_cannot_reach_once_per_uri():
    from vr_driver.ros.graph_watch import SenderWatch
    machine = workstation(**{"ws": ["127.0.1.1"]})
    machine.listening[(DRIVER_PC, 40001)] = None
    master = FakeMaster(
        publishers=[["/joint_trajectory_action/goal", ["/client", "/reachable"]],
                    ["/joint_trajectory_action/cancel", ["/client"]], ["/joint_states", ["/interface"]],
                    ["/other/goal", ["/elsewhere"]]],
        subscribers=[["/joint_trajectory_action/goal", ["/interface"]],
                     ["/joint_trajectory_action/cancel", ["/interface"]], ["/other/goal", ["/someone"]]],
        uris={"/client": "http://ws:40002/", "/reachable": "http://driver-pc:40001/",
              "/elsewhere": "http://ws:40003/"})
    logged = []
    watch = SenderWatch("/interface", master=master, machine=machine, log=logged.append)
    said = watch.poll()
    assert said == logged and len(said) == 1, said        # /reachable is fine, /elsewhere sends elsewhere
    assert said[0].startswith("/interface: nothing /client publishes to it (/joint_trajectory_action/cancel, "
                              "/joint_trajectory_action/goal) arrives: node /client advertises http://ws:40002/, "
                              "which this machine cannot reach (ws = 127.0.1.1 here: connection refused): set ROS_IP")
    assert watch.poll() == []                               # said once
    master.uris["/client"] = "http://192.168.7.20:40004/"  # restarted with ROS_IP: checked again, now fine
    machine.listening[(WORKSTATION, 40004)] = None
    machine.names[WORKSTATION] = [WORKSTATION]
    assert watch.poll() == []
    master.uris["/client"] = "http://ws:40005/"             # and without it again: said again
    assert len(watch.poll()) == 1
