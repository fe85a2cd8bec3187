"""Helpers shared by the nodes (they import rospy): logging to rosout, and signal handling.

Signals: rospy's own SIGINT handler runs the whole ROS shutdown (XML-RPC calls to the master) inside
the handler, on top of whatever the main thread was doing. If that was an XML-RPC call too (e.g.
``get_param`` while an action server starts), rospy's proxy lock is already held and the node
deadlocks on Ctrl-C. Our nodes therefore init with ``disable_signals=True``, let
:func:`stop_on_signals` only set an event, and shut down from the main thread.
"""
from __future__ import annotations

import inspect
import logging
import os
import signal
import threading
from typing import Any, Callable, Optional, Tuple

import rospy


def init_node(name: str, **kwargs: Any) -> None:
    """``rospy.init_node`` for every node of ours, with a shutdown that does not spin.

    rospy's shutdown closes its XML-RPC server's socket while the server's thread still loops in
    ``serve_forever``: from then on the loop's select returns at once, its accept fails, and the
    thread spins at a full core until the process ends -- for the half second to five seconds that
    rospy then joins its registration thread (py-spy on a virtual line at SCHED_FIFO: 92-97 % of a
    CPU in ``serve_forever`` during ``signal_shutdown``; a bus process at SCHED_FIFO 20 beside it went
    7 s without a cycle, and the card's watchdog expired). The first shutdown hook here ends that loop
    before the socket is closed, and puts every thread of the node back at normal scheduling: a node
    that ends has no deadline left (:func:`end_rpc_loop`, :func:`~vr_driver.bus.worker.process_normal_scheduling`)."""
    rospy.init_node(name, **kwargs)
    rospy.on_shutdown(quiet_shutdown)


def quiet_shutdown() -> None:
    """The first shutdown hook of every node of ours (:func:`init_node`): every thread back at normal
    scheduling, rospy's XML-RPC loop ended before its socket closes."""
    from ..bus.worker import process_normal_scheduling
    process_normal_scheduling()
    end_rpc_loop()


def end_rpc_loop() -> Optional[threading.Thread]:
    """Ask this node's XML-RPC server to leave its ``serve_forever`` loop (in a thread of its own: the
    loop notices within its poll interval, or at once once rospy has closed its socket) and its
    node's loop not to serve again. Returns the thread that waits for the loop's end, None when there
    is no server (no node, or ended already).
    rospy keeps its XML-RPC node only as the bound method of one of its shutdown hooks."""
    from rosgraph.xmlrpc import XmlRpcNode
    nodes = [h.__self__ for h in list(rospy.core._shutdown_hooks)
             if inspect.ismethod(h) and isinstance(h.__self__, XmlRpcNode)]
    server = nodes[0].server if nodes else None
    if server is None:
        return None
    nodes[0].is_shutdown = True         # its thread's `while not is_shutdown: serve_forever()` ends
    waiter = threading.Thread(target=server.shutdown, name="xmlrpc-stop", daemon=True)
    waiter.start()
    return waiter


class RosoutHandler(logging.Handler):
    """A logging handler that emits each record through rospy's log functions."""

    def emit(self, record: logging.LogRecord) -> None:
        text = self.format(record)
        if record.levelno >= logging.CRITICAL:
            rospy.logfatal("%s", text)
        elif record.levelno >= logging.ERROR:
            rospy.logerr("%s", text)
        elif record.levelno >= logging.WARNING:
            rospy.logwarn("%s", text)
        elif record.levelno >= logging.INFO:
            rospy.loginfo("%s", text)
        else:
            rospy.logdebug("%s", text)


#: SCHED_FIFO priority of the virtual hardware's nodes (the virtual G2, the line, the I/O island) by
#: default: none (normal scheduling). ``~rt_priority`` N asks for it: the devices stand for hardware,
#: which is never late -- but on a small machine the simulated hardware's CPU is the host's: with
#: three tests side by side, their devices at SCHED_FIFO 30 starved the bus processes past the card's
#: watchdog. (At 10 they once starved the driver nodes too -- joint_states at 13 of 20 /s, a link
#: judged lost: the spin at shutdown, see init_node; scripts/test now runs them at 10.)
VIRTUAL_RT_PRIORITY = 0


def virtual_hardware_priority(name: str) -> str:
    """Ask for SCHED_FIFO ``~rt_priority`` (default VIRTUAL_RT_PRIORITY: 0, normal) for this node's
    threads -- the calling one and those rospy started at init_node
    and the device's (:func:`~vr_driver.bus.worker.set_process_priority` raises every thread the
    process has; later ones inherit it); call it once the device is made and runs, so that its
    set-up (the virtual G2's kinematics) is not real-time work -- and log how it is scheduled, once.
    Returns that, in words.

    Raised, the node goes back to normal scheduling, every thread, as its ROS shutdown begins
    (:func:`init_node`'s first shutdown hook, which also ends rospy's XML-RPC loop before its socket
    closes): that loop busy-loops from the moment its server socket is closed until the process
    ends, and at SCHED_FIFO the three devices' spinning threads took both cores and kept their own
    main threads from ever ending: each node sat out roslaunch's SIGINT and SIGTERM (15 + 2 s) and
    was killed -- at each of a rostest's launches, while everything at normal priority (the other
    lanes' tests) got 5 % of the CPU."""
    from ..bus.worker import set_process_priority
    try:
        priority = int(rospy.get_param("~rt_priority", VIRTUAL_RT_PRIORITY))
    except (TypeError, ValueError):
        rospy.logwarn("%s: ~rt_priority must be an integer 0..99: normal scheduling", name)
        priority = 0
    words = set_process_priority(max(0, min(99, priority)))
    rospy.loginfo("%s: %s (virtual hardware: ~rt_priority)", name, words)
    return words


def own_link(value: Any, station: str) -> Optional[str]:
    """A virtual device's ``~pty_link``: "" or None for no symlink; ``auto`` / ``auto:NAME`` this
    launch's own link of ``station`` / NAME (``controller.pty_link.resolve_link``), its folder made;
    any other value, the path as given."""
    from ..controller.pty_link import AUTO_LINK, resolve_link
    if not value:
        return None
    if not isinstance(value, str):
        from ..controller.simulator import SimError
        raise SimError("~pty_link must be a path, %r or \"\", got %r" % (AUTO_LINK, value))
    if value.startswith(AUTO_LINK):
        value = resolve_link(value, station)
        os.makedirs(os.path.dirname(value), exist_ok=True)
    return value


def open_device(name: str, make: Callable[[], Any]) -> Tuple[Any, int]:
    """``make()``, which opens a virtual device on its serial port, and EXIT_OK; or, after a fatal
    log in words, (None, EXIT_DEVICE) when the port failed, (None, EXIT_USAGE) for a wrong setting."""
    from ..controller.simulator import EXIT_DEVICE, EXIT_OK, EXIT_USAGE, SimDeviceError, SimError
    try:
        return make(), EXIT_OK
    except SimDeviceError as exc:
        rospy.logfatal("%s: device error: %s", name, exc)
        return None, EXIT_DEVICE
    except (SimError, ValueError) as exc:
        rospy.logfatal("%s: %s", name, exc)
        return None, EXIT_USAGE


def route_to_rosout(*names: str, level: int = logging.INFO) -> None:
    """Send the named loggers to rosout only (no propagation, so nothing is logged twice)."""
    for name in names:
        logger = logging.getLogger(name)
        logger.handlers = [h for h in logger.handlers if not isinstance(h, RosoutHandler)]
        logger.addHandler(RosoutHandler())
        logger.setLevel(level)
        logger.propagate = False


def stop_on_signals(*signums: int) -> threading.Event:
    """An event set by SIGINT / SIGTERM (or the given signals); the handler does nothing else."""
    event = threading.Event()

    def handler(signum, _frame):
        event.set()

    for signum in signums or (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, handler)
    return event


def wait_for_shutdown(stop: threading.Event, poll: float = 0.5) -> str:
    """Block until ``stop`` is set or ROS is shut down (e.g. by rosnode kill); return why."""
    while not stop.wait(poll):
        if rospy.is_shutdown():
            return "ROS shutdown"
    return "signal"


def watch_simulator(sim: Any, name: str, stop: threading.Event, hz: float,
                    each: Optional[Callable[[], None]] = None) -> int:
    """A simulator node's main loop: until ``stop``, a ROS shutdown, or an error of ``sim``'s threads
    (logged fatal: its serial device -> EXIT_DEVICE, its program loop -> EXIT_FAILURE), calling
    ``each()`` (if given) ``hz`` times a second. Returns the exit status."""
    from ..controller.simulator import EXIT_DEVICE, EXIT_FAILURE, EXIT_OK
    rate = rospy.Rate(hz)
    while not rospy.is_shutdown() and not stop.is_set():
        if sim.server_error is not None:
            rospy.logfatal("%s: device error: %s", name, sim.server_error)
            return EXIT_DEVICE
        if sim.error is not None:
            rospy.logfatal("%s: program loop failed: %s", name, sim.error)
            return EXIT_FAILURE
        if each is not None:
            each()
        try:
            rate.sleep()
        except rospy.ROSInterruptException:
            break
    return EXIT_OK
