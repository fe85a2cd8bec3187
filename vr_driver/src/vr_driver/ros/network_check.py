"""The ROS graph across machines, checked in words (doc/network.md): the master reachable, this node
reachable by the name it advertises, the other nodes reachable by theirs, the clocks and
``/use_sim_time``.

ROS 1's classic pitfall: every node advertises a URI built from ``ROS_HOSTNAME``, else ``ROS_IP``,
else the machine's host name, and every other node connects to that URI -- the master's callbacks,
the subscribers of its topics, the callers of its services, the action server that must read its
goals. A host name that resolves to 127.0.1.1 (Debian's /etc/hosts), to nothing, or to an address
the other machine cannot reach, breaks the graph without an error: an action client waits for its
server forever, a goal is never seen. These checks say so before, naming what to set.

No ROS here but :func:`advertised_host` (rosgraph's own rule, imported in the function): the
machine is :class:`Machine` (sockets; a test passes its own), every check returns
:class:`Verdict` s, so all of it runs under plain pytest. The node ``check_network``
(:mod:`vr_driver.ros.check_network`) and the pose terminal use it.
"""
from __future__ import annotations

import ipaddress
import os
import socket
import threading
from typing import Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple
from urllib.parse import urlparse

OK, WARNING, ERROR = "ok", "warning", "error"
#: [s] how long a TCP connection to the master or a node may take before it counts as unanswered
CONNECT_TIMEOUT = 2.0
#: [s] a clock offset to the driver's beyond this is worth a warning (the driver refuses a trajectory
#: whose header.stamp is more than 0.5 s in the past: trajectories.validate's late_start)
CLOCK_WARN = 0.1


class Verdict(NamedTuple):
    level: str          # OK, WARNING or ERROR
    text: str

    def line(self) -> str:
        return "%s: %s" % (self.level, self.text)


class Machine:
    """What the checks ask of this machine, over its sockets (a test passes a fake)."""

    def hostname(self) -> str:
        return socket.gethostname()

    def resolve(self, host: str) -> List[str]:
        """The IPv4 addresses ``host`` resolves to here (raises OSError when it does not)."""
        infos = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)
        return sorted({info[4][0] for info in infos})

    def connect(self, address: str, port: int, timeout: float) -> None:
        """Open (and close) a TCP connection; raises OSError (socket.timeout) when it fails."""
        with socket.create_connection((address, port), timeout):
            pass

    def route_source(self, address: str) -> Optional[str]:
        """This machine's own address on the way to ``address`` (the kernel's route; nothing is
        sent), or None when there is no route."""
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            try:
                sock.connect((address, 9))
            except OSError:
                return None
            return sock.getsockname()[0]

    def is_own(self, address: str) -> bool:
        """True when ``address`` is one of this machine's (a socket can be bound to it)."""
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            try:
                sock.bind((address, 0))
            except OSError:
                return False
            return True

    def own_addresses(self) -> List[str]:
        """This machine's IPv4 addresses but loopback, one per interface (Linux: SIOCGIFADDR)."""
        import fcntl
        import struct
        found = []
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            for _index, name in socket.if_nameindex():
                try:
                    raw = fcntl.ioctl(sock.fileno(), 0x8915, struct.pack("256s", name[:15].encode()))
                except OSError:                     # no IPv4 address on it
                    continue
                address = socket.inet_ntoa(raw[20:24])
                if not is_loopback(address) and address not in found:
                    found.append(address)
        return found


def is_loopback(address: str) -> bool:
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


def advertised_host(env: Mapping[str, str] = os.environ) -> Tuple[str, str]:
    """(the host this process's nodes advertise in their URIs, where it comes from in words), by
    rosgraph's own rule (``__hostname:=`` / ``__ip:=``, then ROS_HOSTNAME, then ROS_IP, then the
    host name)."""
    from rosgraph.network import get_host_name
    host = get_host_name()
    if env.get("ROS_HOSTNAME"):
        return host, "ROS_HOSTNAME"
    if env.get("ROS_IP"):
        return host, "ROS_IP"
    return host, "the host name; ROS_IP and ROS_HOSTNAME are unset"


def master_address(uri: Optional[str]) -> Tuple[Optional[Tuple[str, int]], Optional[Verdict]]:
    """(host, port) of ROS_MASTER_URI, or an ERROR saying what is wrong with it."""
    if not uri:
        return None, Verdict(ERROR, "ROS_MASTER_URI is not set: set it to the master's URI, e.g. "
                                    "ROS_MASTER_URI=http://<driver PC's address>:11311")
    parts = urlparse(uri)
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme != "http" or not parts.hostname or port is None:
        return None, Verdict(ERROR, "ROS_MASTER_URI=%s is not a master URI: the form is http://HOST:PORT, "
                                    "e.g. http://192.168.1.10:11311" % uri)
    return (parts.hostname, port), None


def check_master(uri: Optional[str], machine: Machine, timeout: float = CONNECT_TIMEOUT
                 ) -> Tuple[Verdict, Optional[str]]:
    """Whether the master at ``uri`` answers a TCP connection: (verdict, the master's address, None
    when it is not known)."""
    where, wrong = master_address(uri)
    if wrong is not None:
        return wrong, None
    host, port = where
    try:
        address = machine.resolve(host)[0]
    except (OSError, IndexError):
        return Verdict(ERROR, "cannot reach the ROS master at %s (ROS_MASTER_URI): its host name %r does "
                              "not resolve on this machine; put the driver PC's address in ROS_MASTER_URI "
                              "(http://<address>:%d) or the name in /etc/hosts" % (uri, host, port)), None
    why = _connect(machine, address, port, timeout)
    if why is not None:
        return Verdict(ERROR, "cannot reach the ROS master at %s (ROS_MASTER_URI; %s): %s" % (
            uri, address, _master_hint(why, port))), address
    return Verdict(OK, "the ROS master at %s answers (%s)" % (uri, address)), address


def _connect(machine: Machine, address: str, port: int, timeout: float) -> Optional[str]:
    """None when a TCP connection opens, else what happened in a word or two."""
    try:
        machine.connect(address, port, timeout)
    except socket.timeout:
        return "no answer within %.0f s" % timeout
    except ConnectionRefusedError:
        return "connection refused"
    except OSError as exc:
        return exc.strerror or str(exc)
    return None


def _master_hint(why: str, port: int) -> str:
    if why == "connection refused":
        return ("connection refused: nothing listens on port %d there; is roscore (driver_pc.launch) "
                "running on that machine, and is the port right?" % port)
    if why.startswith("no answer"):
        return ("%s: a firewall between the machines drops it (open TCP port %d and the nodes' ports, "
                "doc/network.md), or the address is not the master's" % (why, port))
    return "%s: is this machine on the master's network (address, cable, interface)?" % why


def check_own_host(host: str, source: str, master: Optional[str], machine: Machine,
                   remote_clients: bool = False) -> Verdict:
    """Whether nodes on other machines can reach this machine's nodes by the host they advertise.

    ``master``: the master's address (None: unknown). A master on another machine must reach this
    one; with ``remote_clients`` (the driver PC beside its own master) the other machines' nodes
    must. The address to set is this machine's own toward the master, or, for remote clients, its
    addresses but loopback."""
    if ":" in host:
        return Verdict(WARNING, "this machine's nodes advertise %r (%s), an IPv6 address: not checked (these "
                                "checks know IPv4 only)" % (host, source))
    remote_master = master is not None and not is_loopback(master) and not machine.is_own(master)
    if master is None and not remote_clients:
        return Verdict(WARNING, "this machine's nodes advertise %r (%s); not checked: the master's address "
                                "is not known" % (host, source))
    if not (remote_master or remote_clients):
        return Verdict(OK, "this machine's nodes advertise %r (%s); the master is on this machine"
                       % (host, source))
    if remote_master:
        toward = machine.route_source(master)
        candidates = [toward] if toward else []
        who = "the master at %s and its machine's nodes" % master
        where = "this machine's address toward the master"
    else:
        candidates = machine.own_addresses()
        who = "nodes on other machines (the workstation)"
        where = "this machine's address on the workstations' network"
    fix = _fix(candidates, where)
    try:
        addresses = machine.resolve(host)
    except OSError:
        addresses = []
    said = "this machine's nodes advertise %r (%s)" % (host, source)
    if not addresses:
        return Verdict(ERROR, "%s, which does not resolve here: %s cannot connect to them; %s" % (said, who, fix))
    if all(is_loopback(a) for a in addresses):
        return Verdict(ERROR, "%s, which is %s (loopback): %s would connect to themselves, and every "
                              "goal, service call and topic from here is lost without an error; %s"
                       % (said, "/".join(addresses), who, fix))
    foreign = [a for a in addresses if not machine.is_own(a)]
    if len(foreign) == len(addresses):
        return Verdict(ERROR, "%s, which is %s: not an address of this machine; %s"
                       % (said, "/".join(addresses), fix))
    if source == "ROS_HOSTNAME":
        said += " = %s here; the other machines must resolve %r to it too" % ("/".join(addresses), host)
    if remote_master and candidates and candidates[0] not in addresses:
        return Verdict(WARNING, "%s, but it reaches the master from %s: the master's machine must route to "
                                "%s; if it cannot, %s" % (said, candidates[0], "/".join(addresses), fix))
    if source != "ROS_HOSTNAME" and addresses != [host]:
        said += " = %s" % "/".join(addresses)
    return Verdict(OK, said)


def _fix(candidates: Sequence[str], where: str) -> str:
    if not candidates:
        return "set ROS_IP to %s (or ROS_HOSTNAME to a name every machine resolves to it)" % where
    return "set ROS_IP=%s (%s%s) before starting nodes here, or ROS_HOSTNAME to a name every machine " \
           "resolves to it" % (" or ROS_IP=".join(candidates), where,
                               ", one of them" if len(candidates) > 1 else "")


def check_nodes(nodes: Mapping[str, str], machine: Machine, timeout: float = CONNECT_TIMEOUT) -> List[Verdict]:
    """Whether this machine reaches every node by the URI it advertises (name -> XML-RPC URI), all
    at once (one thread each): an ERROR per node it cannot, naming the host, what it resolves to here
    and what to set on the node's machine; one OK line for the rest (an IPv6 host counts there: not
    judged)."""
    results: Dict[str, Optional[str]] = {}

    def probe(name: str, uri: str) -> None:
        parts = urlparse(uri)
        if ":" in (parts.hostname or ""):      # IPv6 (ROS_IPV6): not judged, these checks know IPv4 only
            results[name] = None
            return
        try:
            address = machine.resolve(parts.hostname or "")[0]
        except (OSError, IndexError):
            results[name] = "%r does not resolve here" % parts.hostname
            return
        why = _connect(machine, address, parts.port or 0, timeout)
        shown = parts.hostname if parts.hostname == address else "%s = %s here" % (parts.hostname, address)
        results[name] = None if why is None else "%s: %s" % (shown, why)
    threads = [threading.Thread(target=probe, args=item, daemon=True) for item in sorted(nodes.items())]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout + 5.0)
    bad = [Verdict(ERROR, "node %s advertises %s, which this machine cannot reach (%s): set ROS_IP to its "
                          "machine's address on this network there (or make the name resolve to it here, "
                          "/etc/hosts)" % (name, nodes[name], results.get(name) or "no answer"))
           for name in sorted(nodes) if results.get(name, "no answer") is not None]
    good = len(nodes) - len(bad)
    return bad + ([Verdict(OK, "%d node%s reachable by the URIs they advertise" % (good, "" if good == 1 else "s"))]
                  if good else [])


def check_clock(offset: Optional[float], source: str) -> Verdict:
    """``offset``: this clock minus the driver's [s], from a stamped message of ``source`` (its transit
    included, so a little high); None: no message came."""
    if offset is None:
        return Verdict(WARNING, "clock not compared: no %s message came" % source)
    said = "this clock is %+.3f s from the driver's (%s stamps, transit included)" % (offset, source)
    if abs(offset) <= CLOCK_WARN:
        return Verdict(OK, said)
    if offset > 0:
        effect = ("a trajectory stamped here (header.stamp = now) starts that much late: the driver waits "
                  "for its stamp")
    else:
        effect = ("a trajectory stamped here (header.stamp = now) arrives that far in the driver's past: it "
                  "runs late on its timing, and the driver refuses one more than 0.5 s in the past")
    return Verdict(WARNING if abs(offset) < 0.5 else ERROR,
                   "%s: %s; synchronise the clocks (chrony, doc/network.md)" % (said, effect))


def check_sim_time(use_sim_time: object, clock_publishers: Sequence[str]) -> Verdict:
    if use_sim_time is None or use_sim_time is False:
        return Verdict(OK, "/use_sim_time is %s: ROS time is the wall clock, as the driver needs" % (
            "unset" if use_sim_time is None else "false"))
    who = ("/clock is published by %s" % ", ".join(clock_publishers) if clock_publishers
           else "nobody publishes /clock, so ROS time stands still")
    return Verdict(ERROR, "/use_sim_time is %r: %s; the driver and the G2 run on real time: set it false "
                          "(rosparam set /use_sim_time false, and restart the nodes)" % (use_sim_time, who))


def own_host_error(uri: Optional[str], machine: Optional[Machine] = None) -> Optional[str]:
    """For a client about to start its node (the pose terminal): the words of
    :func:`check_own_host`'s ERROR against the master at ``uri``, or None (also when the master's
    address is not known: :func:`check_master` says that)."""
    machine = machine or Machine()
    where, _wrong = master_address(uri)
    if where is None:
        return None
    try:
        master = machine.resolve(where[0])[0]
    except (OSError, IndexError):
        return None
    host, source = advertised_host()
    verdict = check_own_host(host, source, master, machine)
    return verdict.text if verdict.level == ERROR else None


__all__ = ["OK", "WARNING", "ERROR", "Verdict", "Machine", "advertised_host", "master_address", "check_master",
           "check_own_host", "own_host_error", "check_nodes", "check_clock", "check_sim_time", "is_loopback"]
