"""The driver's parameters: one validated, immutable record built from a plain mapping.

ROS-free: the node passes ``rospy.get_param("~")`` (a dict), tests pass dicts. Every value is
checked at start; a bad one raises :class:`ParamError` naming the parameter, its value and what
is allowed, and the node exits with that message. The documented defaults live in
``config/vr_driver.yaml``; the same defaults are here so the core runs without ROS.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field, fields, replace
from operator import attrgetter
from types import ModuleType
from typing import TYPE_CHECKING, Any, Dict, List, Mapping, Optional, Tuple

from . import validate
from .errors import SignalMapError, VrDriverError
from .io_signals import CONTROLLER_IO_LENGTH, SignalMap, lengths_from_bus, load_signal_map
from .poses import ControllerPose, Workspace

if TYPE_CHECKING:
    from pyprofibus_vendor.config import BusConfig

#: parameters as the node (rospy.get_param) or a test gives them: a mapping whose values are not
#: checked yet
RawParams = Mapping[str, Any]
DEFAULT_PORT = "/dev/ttyUSB0"
DEFAULT_JOINT_NAMES = tuple("joint_%d" % i for i in range(1, 7))
#: the DP watchdog's largest value: factors 255 x 255 x 10 ms
WATCHDOG_MAX_MS = 650_250
#: the planners ``planner_id`` may name (OMPL geometric planners; kinematics.planner runs them);
#: RRTConnect is MoveIt's default, too
PLANNERS = ("RRTConnect", "RRT", "RRTstar", "InformedRRTstar", "BITstar", "PRM", "PRMstar",
            "KPIECE1", "BKPIECE1", "LBKPIECE1", "FMT", "AORRTC")
#: the value of a simulated station's ``pty_link`` (and of the driver's ``port``) that means "this
#: launch's own link"
AUTO_LINK = "auto"
#: a name prefix (``left_``, ``arm1_``): empty, or a letter then letters, digits and underscores --
#: the characters a TF frame, a URDF link and a ROS name fragment all accept
PREFIX_PATTERN = re.compile(r"\A(?:[A-Za-z][A-Za-z0-9_]*)?\Z")


def _registry() -> ModuleType:
    """:mod:`vr_driver.protocol.registry`, the protocol objects by name (doc/controller_program.md):
    the one import of this module from a layer above it, lazy (``test_layout.KNOWN``). The
    ``protocol`` parameter is checked against the registered objects (a streaming one changes what
    ``stream_smooth`` may be) and resolved to one (:attr:`DriverParams.wire`, the bus's modules and
    lengths); the registry holds the protocols' code, so it cannot move down into the vocabulary."""
    from .protocol import registry
    return registry


def _stream_smooth(protocol: str, facts: "ControllerFacts", stream_smooth: int) -> int:
    """``stream_smooth`` for the commissioned G2: 0 where it reads no MOVE ahead on a streaming
    protocol (it stops at every point anyway: each is timed as a stop), or where its look-ahead was
    not measured (``controller/not_measured``: a program whose loop blocked during a MOVE hid it). A program loop that stops
    while a MOVE runs cannot serve a streaming protocol: ParamError naming
    ``controller/loop_blocks_during_move`` and the protocol that works."""
    registry = _registry()
    if not registry.get(protocol).streams:
        return stream_smooth
    if facts.loop_blocks_during_move:
        raise ParamError("controller/loop_blocks_during_move", True,
                         "the G2's program loop stops while a MOVE runs: protocol %s cannot stream with it "
                         "(the feedback freezes while the arm moves, a target is taken only between MOVEs, "
                         "STOP is not seen until the move ends) -- use protocol %s (doc/commissioning.md)"
                         % (protocol, registry.DEFAULT))
    if facts.interpreter_lookahead == 0 or "interpreter_lookahead" in facts.not_measured:
        return 0          # not measured: the safe side (a stop at every point runs on any look-ahead)
    return stream_smooth


def _io_protocols() -> Tuple[str, ...]:
    """The protocols whose records carry the controller's own I/O."""
    registry = _registry()
    return tuple(name for name in registry.names() if registry.get(name).controller_io)


class ParamError(VrDriverError, ValueError):
    """A bad driver parameter. ``name`` is the parameter (e.g. ``workspace/x``)."""

    def __init__(self, name: str, value: object, reason: str) -> None:
        self.name = name
        self.value = value
        self.reason = reason
        super().__init__("parameter ~%s = %r: %s" % (name, value, reason))


def _number(params: RawParams, name: str, default: float, lo: float, hi: float,
            lo_open: bool = False) -> float:
    value = params.get(name, default)

    def fail(got: Optional[float]) -> ParamError:
        if got is None:
            return ParamError(name, value, "expected a finite number")
        return ParamError(name, value, "must be in %s%g, %g]" % ("(" if lo_open else "[", lo, hi))
    return validate.number(value, fail, lo, hi, lo_open=lo_open, text=False)


def _integer(params: RawParams, name: str, default: Optional[int], lo: int, hi: int
             ) -> Optional[int]:
    value = params.get(name, default)
    if value is None:
        return None
    return validate.integer(value, lambda got: ParamError(
        name, value, "expected an integer" if got is None else "must be in [%d, %d]" % (lo, hi)), lo, hi)


def _string(params: RawParams, name: str, default: str, allowed: Tuple[str, ...] = ()
            ) -> str:
    value = params.get(name, default)
    if not isinstance(value, str):
        raise ParamError(name, value, "expected a string")
    if allowed and value not in allowed:
        raise ParamError(name, value, "must be one of %s" % ", ".join(allowed))
    return value


def _port(params: RawParams, default: str) -> str:
    """``port``; ``auto`` becomes the link the virtual controller of this launch makes (the same
    resolution as its ``pty_link: auto``, :func:`resolve_link`); ``auto:NAME`` this launch's link of
    station NAME (``auto:line``: the virtual line's master end)."""
    value = _string(params, "port", default)
    try:
        return resolve_link(value)
    except LinkNameError as exc:
        raise ParamError("port", value, str(exc)) from None


def _prefix(params: RawParams, default: str) -> str:
    value = _string(params, "prefix", default)
    if not PREFIX_PATTERN.match(value):
        raise ParamError("prefix", value, "expected empty or a letter followed by letters, digits "
                         "and underscores (e.g. left_)")
    return value


def prefixed(prefix: str, names: "Tuple[str, ...]") -> Tuple[str, ...]:
    """``names`` with ``prefix`` in front of each (the empty prefix leaves them as they are)."""
    return tuple(prefix + name for name in names)


class LinkNameError(VrDriverError, ValueError):
    """``auto`` cannot be resolved: no port in ROS_MASTER_URI, or a bad station name."""


def auto_link(environ: Optional[Mapping[str, str]] = None, station: str = "g2") -> str:
    """This launch's link of a simulated station: ``<ROS log dir>/vr006l_virtual_<station>_<master
    port>`` (``station`` ``g2`` the virtual controller, ``io_island`` the virtual I/O island, ``line``
    the line hub's master end, :mod:`vr_driver.controller.line`), followed by ``_<namespace>`` for
    nodes in a namespace (``/arm1`` -> ``..._11311_arm1``, ``/cell/arm1`` -> ``..._11311_cell_arm1``).

    The simulated stations (controller.pty_link.auto_pty_link) and the driver (``port: auto``)
    resolve ``auto`` with this function from the environment roslaunch gives its nodes
    (ROS_MASTER_URI; ROS_NAMESPACE, set for the nodes of a ``<group ns>``; ROS_LOG_DIR, else
    ROS_HOME/log, else ~/.ros/log), so they agree on the path, launches on different masters never
    share one, and two drivers in two namespaces of one launch get one each. LinkNameError."""
    env = os.environ if environ is None else environ
    uri = env.get("ROS_MASTER_URI", "") or "http://localhost:11311"
    port = uri.rstrip("/").rsplit(":", 1)[-1]
    if not port.isdigit():
        raise LinkNameError("cannot take a port from ROS_MASTER_URI=%r for pty_link %r" % (uri, AUTO_LINK))
    log_dir = env.get("ROS_LOG_DIR") or os.path.join(
        env.get("ROS_HOME") or os.path.join(os.path.expanduser("~"), ".ros"), "log")
    if not re.match(r"[A-Za-z0-9_]+\Z", station):
        raise LinkNameError("bad station name %r for an auto pty link" % (station,))
    ns = "_".join(part for part in (env.get("ROS_NAMESPACE") or "").split("/") if part)
    return os.path.join(log_dir, "vr006l_virtual_%s_%s" % (station, port) + ("_" + ns if ns else ""))


def resolve_link(value: str, station: str = "g2") -> str:
    """A link given as a parameter: ``auto`` is this launch's link of ``station``, ``auto:NAME``
    this launch's link of station NAME (:func:`auto_link`); anything else is a path."""
    if value == AUTO_LINK:
        return auto_link(station=station)
    if value.startswith(AUTO_LINK + ":"):
        return auto_link(station=value[len(AUTO_LINK) + 1:])
    return value


def _boolean(params: RawParams, name: str, default: bool) -> bool:
    value = params.get(name, default)
    if not isinstance(value, bool):
        raise ParamError(name, value, "expected true or false")
    return value


def _vector(params: RawParams, name: str, default: Tuple[float, ...], length: int
            ) -> Tuple[float, ...]:
    value = params.get(name, default)
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise ParamError(name, value, "expected a list of %d numbers" % length)
    return tuple(validate.number(item, lambda _: ParamError(name, value, "expected a list of %d finite numbers"
                                                            % length), text=False) for item in value)


def _model(params: RawParams, default: str) -> str:
    """``model``: "" or a kinematics YAML that panasonic_vr006l_support.true_model accepts (checked
    here, at start: a missing or bad file is a ParamError naming ``model`` with the file's key)."""
    value = _string(params, "model", default)
    if not value:
        return value
    if not os.path.isfile(value):
        raise ParamError("model", value, "no such file")
    from panasonic_vr006l_support import true_model
    try:
        true_model.load(value)
    except (true_model.TrueModelError, OSError) as exc:
        raise ParamError("model", value, str(exc)) from None
    return value


#: the joint solution the G2 takes for a Cartesian target (doc/controller_program.md §10.9)
CONFIGURATION_RULES = ("previous_target", "current_joints")
#: what the G2's program does with a target one number ahead of the next it takes: waits (accepted),
#: refuses it OUT_OF_ORDER (refused), or runs it (taken: exactly once broken by the program)
SEND_AHEAD_RULES = ("accepted", "refused", "taken")
#: what an unreachable pose does: refused UNREACHABLE (skip) or an alarm that halts the program
UNREACHABLE_RULES = ("skip", "alarm_halt")
RAMP_SHAPES = ("linear", "s_curve")


@dataclass(frozen=True)
class ControllerFacts:
    """What the G2 does where the design only assumes (doc/controller_program.md §10.9): the
    ``controller:`` mapping of the parameters, as ``rosrun vr_driver commission`` measured it
    (doc/commissioning.md). The defaults are the assumptions (the virtual G2's defaults): a driver
    without a commissioning file runs as before. Every value is range-checked at start; a bad one is a
    ParamError naming ``controller/<key>``. What the driver does with them:
    :mod:`vr_driver.driver.checks.commissioned` (the words it says at connect, the stream timing, the
    planner's limits) and :class:`DriverParams` (a program loop that blocks during a MOVE refuses a
    streaming protocol; no look-ahead makes every stream point a stop, ``stream_smooth`` 0; a target
    sent ahead refused: one target per acknowledgement, :attr:`DriverParams.wire`)."""

    interpreter_lookahead: int = 1       # MOVEs the G2's interpreter reads ahead of the one running
    #                                      (0: each point a stop; 2: shorter stream segments feed it)
    loop_period: float = 0.01            # [s] the program loop's period at rest (information)
    loop_period_spread: float = 0.0      # [s] its spread (information: joint_states stamps may be
    #                                      early by up to it)
    loop_blocks_during_move: bool = False   # the program loop stops while a MOVE runs (no streaming)
    speed_scale: float = 1.0             # MOVEP's speed unit: the real speed per commanded speed
    #                                      (0.6: "speed 1000" is 60 % of the joint limits)
    configuration: str = "previous_target"   # the joint solution of a Cartesian target: the tracker and v3's stream check apply it
    send_ahead: str = "accepted"         # a target one number ahead (SEND_AHEAD_RULES)
    unreachable: str = "skip"            # an unreachable pose (UNREACHABLE_RULES; information)
    ring_size: int = 4                   # targets the program's ring holds (information)
    ramp_shape: str = "linear"           # the arm's speed ramps (RAMP_SHAPES; information)
    ramp_time: Optional[float] = None    # [s] rest to full speed of the slowest-ramping joint
    #                                      measured; None: not measured (the model's)
    accelerations: Tuple[Tuple[str, float], ...] = ()   # (plain joint name, rad/s^2) measured
    check_word: bool = True              # the program checks the master's check word and seq copy
    not_measured: Tuple[str, ...] = ()   # keys the commissioning could not measure (the bus hid them):
    #                                      their assumptions stand, and interpreter_lookahead among them
    #                                      makes every stream point a stop (stream_smooth 0)
    program_speed: float = 10.0          # [m/min] v1: the program's MOVEP speed (a PTP target)
    program_path_speed: float = 5.0      # [m/min] v1: its MOVEL / MOVEC speed (a LIN, a CIRC)

    @classmethod
    def from_dict(cls, value: object, joint_names: Tuple[str, ...]) -> "ControllerFacts":
        """Validate the ``controller`` mapping (missing keys: the assumptions; unknown keys are
        errors). ``joint_names``: the plain joint names ``accelerations`` may name."""
        if value is None:
            value = {}
        if not isinstance(value, Mapping):
            raise ParamError("controller", value, "expected a mapping of the G2's measured behaviours "
                             "(doc/commissioning.md)")
        known = [f.name for f in fields(cls)]
        unknown = sorted(set(value) - set(known))
        if unknown:
            raise ParamError("controller/%s" % unknown[0], value[unknown[0]],
                             "unknown key (known: %s)" % ", ".join(known))
        d = cls()
        try:
            ramp = value.get("ramp_time")
            return cls(
                interpreter_lookahead=_integer(value, "interpreter_lookahead", d.interpreter_lookahead, 0, 16),
                loop_period=_number(value, "loop_period", d.loop_period, 0.0, 1.0, lo_open=True),
                loop_period_spread=_number(value, "loop_period_spread", d.loop_period_spread, 0.0, 1.0),
                loop_blocks_during_move=_boolean(value, "loop_blocks_during_move", d.loop_blocks_during_move),
                speed_scale=_number(value, "speed_scale", d.speed_scale, 0.0, 10.0, lo_open=True),
                configuration=_string(value, "configuration", d.configuration, CONFIGURATION_RULES),
                send_ahead=_string(value, "send_ahead", d.send_ahead, SEND_AHEAD_RULES),
                unreachable=_string(value, "unreachable", d.unreachable, UNREACHABLE_RULES),
                ring_size=_integer(value, "ring_size", d.ring_size, 1, 1000),
                ramp_shape=_string(value, "ramp_shape", d.ramp_shape, RAMP_SHAPES),
                ramp_time=None if ramp is None else _number(value, "ramp_time", 0.0, 0.0, 10.0),
                accelerations=_accelerations(value.get("accelerations"), joint_names),
                check_word=_boolean(value, "check_word", d.check_word),
                not_measured=_not_measured(value, known),
                program_speed=_number(value, "program_speed", d.program_speed, 0.0, 1000.0, lo_open=True),
                program_path_speed=_number(value, "program_path_speed", d.program_path_speed, 0.0, 1000.0,
                                           lo_open=True),
            )
        except ParamError as exc:
            if exc.name.startswith("controller/"):
                raise
            raise ParamError("controller/" + exc.name, exc.value, exc.reason) from None

    def acceleration(self, name: str) -> Optional[float]:
        """The measured acceleration [rad/s^2] of the joint called ``name`` (plain), or None."""
        return dict(self.accelerations).get(name)


def _not_measured(value: RawParams, known: List[str]) -> Tuple[str, ...]:
    """``controller/not_measured``: a list of the other keys. A key listed keeps the value it is given
    (the config file's: the assumption), and the driver treats it as not measured."""
    names = value.get("not_measured")
    if names is None:
        return ()
    if isinstance(names, str) or not isinstance(names, (list, tuple)):
        raise ParamError("controller/not_measured", names, "expected a list of controller keys")
    out = []
    for name in names:
        if name not in known or name == "not_measured":
            raise ParamError("controller/not_measured", names, "%r is no controller key (known: %s)"
                             % (name, ", ".join(k for k in known if k != "not_measured")))
        out.append(str(name))
    return tuple(sorted(set(out)))


def _accelerations(value: object, joint_names: Tuple[str, ...]) -> Tuple[Tuple[str, float], ...]:
    """``controller/accelerations``: {plain joint name: rad/s^2 in (0, 1000]}, or empty."""
    if value is None:
        return ()
    if not isinstance(value, Mapping):
        raise ParamError("controller/accelerations", value, "expected a mapping {joint name: rad/s^2}")
    out = []
    for name in sorted(value):
        if name not in joint_names:
            raise ParamError("controller/accelerations/%s" % name, value[name],
                             "not a joint of the arm (%s)" % ", ".join(joint_names))
        out.append((name, _number(value, name, 0.0, 0.0, 1000.0, lo_open=True)))
    return tuple(out)


def read_planning_limits(path: str, joint_names: Tuple[str, ...]
                         ) -> Tuple[Tuple[float, ...], Tuple[float, ...]]:
    """(velocities [rad/s], accelerations [rad/s^2]) of ``joint_names`` (plain) from a MoveIt
    ``joint_limits.yaml`` (the layout of panasonic_vr006l_moveit_config/config/joint_limits.yaml, e.g.
    the one ``commission`` writes beside its file). ParamError naming ``planning_limits`` and the
    joint and key for a missing file, a missing joint, or a limit that is not a number > 0."""
    import yaml
    if not os.path.isfile(path):
        raise ParamError("planning_limits", path, "no such file")
    try:
        with open(path, encoding="utf-8") as fh:
            doc = yaml.safe_load(fh)
    except (OSError, yaml.YAMLError) as exc:
        raise ParamError("planning_limits", path, "cannot read it: %s" % exc) from None
    limits = doc.get("joint_limits") if isinstance(doc, Mapping) else None
    if not isinstance(limits, Mapping):
        raise ParamError("planning_limits", path, "expected a mapping joint_limits: {joint: {max_velocity, "
                         "max_acceleration, ...}} (MoveIt's joint_limits.yaml)")
    velocity, acceleration = [], []
    for name in joint_names:
        entry = limits.get(name)
        if not isinstance(entry, Mapping):
            raise ParamError("planning_limits", path, "joint_limits/%s: missing (every joint of the arm: %s)"
                             % (name, ", ".join(joint_names)))
        for key, out in (("max_velocity", velocity), ("max_acceleration", acceleration)):
            flag = "has_" + key[4:] + "_limits"
            if entry.get(flag) is not True:
                raise ParamError("planning_limits", path, "joint_limits/%s/%s: must be true (the planner "
                                 "needs both limits of every joint)" % (name, flag))
            out.append(validate.number(entry.get(key), lambda _: ParamError(
                "planning_limits", path, "joint_limits/%s/%s: expected a number > 0, got %r"
                % (name, key, entry.get(key))), 0.0, 1e6, lo_open=True, text=False))
    return tuple(velocity), tuple(acceleration)


def _cycles(name: str, value: float, cycle_rate: float, why: str = "") -> None:
    """ParamError naming ``name`` unless ``value`` [s] covers two bus cycles at ``cycle_rate``."""
    if value < 2.0 / cycle_rate:
        raise ParamError(name, value, "must cover at least two bus cycles (>= %g s at cycle_rate %g Hz)%s"
                         % (2.0 / cycle_rate, cycle_rate, why))


def _existing_file(params: RawParams, name: str, default: str) -> str:
    """A string parameter naming a file: "" or a file that exists."""
    value = _string(params, name, default)
    if value and not os.path.isfile(value):
        raise ParamError(name, value, "no such file")
    return value


@dataclass(frozen=True)
class LinkParams:
    """The link to the controller: the protocol, the bus and its process (config/vr_driver.yaml,
    "link to the controller")."""

    protocol: str = "v1"                 # the robot program's protocol (vr_driver.protocol; both ends alike)
    bus_config: str = ""                 # "" = pyprofibus_vendor's default robot bus (vr006l_bus.yaml)
    io_signals: str = ""                 # signal map of the I/O stations beside the controller
    #                                      (doc/io_line.md); "" = none: only the controller is cycled
    port: str = ""                       # "" = the bus config's phy.device (default /dev/ttyUSB0);
    #                                      "auto" = this launch's virtual controller link (resolved)
    baud: Optional[int] = None           # None = the bus config's baud
    master_address: Optional[int] = None
    slave_address: int = 4
    watchdog_ms: Optional[int] = None    # None = the bus config's value; 0 = off (needs
                                         # allow_no_watchdog)
    allow_no_watchdog: bool = False      # accept a watchdog of 0 (the arm no longer stops when the
                                         # master dies); warned at every start
    cycle_rate: float = 15.0             # Data_Exchange cycles per second (19.2 kbit/s with the I/O island)
    byte_order: str = "little"
    link_timeout: float = 0.5            # no good reply for this long = link lost [s]
    reconnect_period: float = 0.5        # between reopen attempts while the link is lost [s]
    # the bus in a process of its own (vr_driver.bus.process): nothing the node computes delays a cycle
    bus_process: bool = True             # False: the DP master in the node's bus thread (as before 0.3)
    bus_rt_priority: int = 20            # SCHED_FIFO priority of the bus process where the system
    #                                      allows it (doc/reliability.md, "Real-time priority"); 0: normal
    bus_node_timeout: float = 3.0        # [s] the node silent this long is dead to the bus process
    #                                      (a dead node is seen at once: its socket closes)
    bus_stop_hold: float = 2.0           # [s] after the node died: the stop record this long, then the
    #                                      bus process closes the port (the card's watchdog follows)

    @classmethod
    def from_dict(cls, params: RawParams) -> "LinkParams":
        d = cls()
        bus_config = _existing_file(params, "bus_config", d.bus_config)
        io_signals = _existing_file(params, "io_signals", d.io_signals)
        out = cls(
            protocol=_string(params, "protocol", d.protocol, _registry().names()),
            bus_config=bus_config,
            io_signals=io_signals,
            port=_port(params, d.port),
            baud=_integer(params, "baud", d.baud, 9600, 12_000_000),
            master_address=_integer(params, "master_address", d.master_address, 0, 125),
            slave_address=_integer(params, "slave_address", d.slave_address, 0, 125),
            watchdog_ms=_integer(params, "watchdog_ms", d.watchdog_ms, 0, WATCHDOG_MAX_MS),
            allow_no_watchdog=_boolean(params, "allow_no_watchdog", d.allow_no_watchdog),
            cycle_rate=_number(params, "cycle_rate", d.cycle_rate, 0.0, 1000.0, lo_open=True),
            byte_order=_string(params, "byte_order", d.byte_order, ("little", "big")),
            link_timeout=_number(params, "link_timeout", d.link_timeout, 0.0, 10.0, lo_open=True),
            reconnect_period=_number(params, "reconnect_period", d.reconnect_period, 0.05, 1.0),
            bus_process=_boolean(params, "bus_process", d.bus_process),
            bus_rt_priority=_integer(params, "bus_rt_priority", d.bus_rt_priority, 0, 99),
            bus_node_timeout=_number(params, "bus_node_timeout", d.bus_node_timeout, 0.1, 60.0),
            bus_stop_hold=_number(params, "bus_stop_hold", d.bus_stop_hold, 0.0, 60.0),
        )
        _cycles("link_timeout", out.link_timeout, out.cycle_rate)
        _cycles("bus_node_timeout", out.bus_node_timeout, out.cycle_rate)
        if out.watchdog_ms is not None:
            out.check_watchdog(out.watchdog_ms, "watchdog_ms")
        return out

    def check_watchdog(self, watchdog_ms: Optional[int], source: str) -> None:
        """The controller card's watchdog against the bus cycle and ``link_timeout``:
        ParamError naming ``watchdog_ms`` (``source`` says where the value came from).

        - at least two bus cycles: the card drops Data_Exchange (and the controller stops the arm)
          when the master is silent for the watchdog time, so a shorter one fires between cycles
          and the link never comes up;
        - at most ``link_timeout``: when the master dies, the arm is stopped by the card before the
          driver would call the link lost -- an arm never moves longer than the driver's own limit;
        - 0 (off) only with ``allow_no_watchdog: true`` (then the arm keeps going when the master
          dies; the node warns at every start).
        """
        value = watchdog_ms or 0
        if value == 0:
            if not self.allow_no_watchdog:
                raise ParamError("watchdog_ms", watchdog_ms,
                                 "0 switches the card's watchdog off: the arm would no longer stop "
                                 "when the master dies; set allow_no_watchdog: true to accept that "
                                 "(from %s)" % source)
            return
        low = 2000.0 / self.cycle_rate
        if value < low:
            raise ParamError("watchdog_ms", watchdog_ms,
                             "must be at least two bus cycles (>= %g ms at cycle_rate %g Hz), or the "
                             "card drops Data_Exchange between cycles and the link never comes up "
                             "(from %s)" % (math.ceil(low), self.cycle_rate, source))
        if value > 1000.0 * self.link_timeout:
            raise ParamError("watchdog_ms", watchdog_ms,
                             "must not exceed link_timeout (%g ms): when the master dies the card "
                             "must stop the arm before the driver calls the link lost "
                             "(from %s)" % (1000.0 * self.link_timeout, source))


@dataclass(frozen=True)
class MotionParams:
    """The handshake, the streams and the plan action's defaults."""

    # handshake
    accept_timeout: float = 1.0          # target sent -> controller busy/done [s]
    release_timeout: float = 1.0         # flag cleared -> controller ready [s]
    motion_timeout_factor: float = 3.0   # motion timeout = factor * preview duration + margin
    motion_timeout_margin: float = 5.0   # [s]
    stop_settle_time: float = 0.25       # a stopped arm is at rest: in-motion clear and the pose
                                         # unchanged this long [s]
    stop_timeout: float = 10.0           # a stop that does not reach rest this long fails [s]
    # streaming (protocol v2)
    stream_smooth: int = 3               # smooth level of the points a stream passes through
                                         # (0 = stop at each; the last point always stops exactly)
    joint_command_timeout: float = 0.2   # [s] joint_command: no command for this long ends the
                                         # stream (the arm rests at the last accepted target); each
                                         # command's step must be done within it (speed check)
    stream_path_tolerance: float = 0.1   # [deg] a v2 stream drops planned points whose removal keeps
                                         # the path within this (a straight joint-space chord); also
                                         # what a blended corner may round off (the smooth level)
    # the plan action (vr_driver.kinematics.planner): what a goal that leaves them 0 / empty gets
    planner_id: str = "RRTConnect"       # the OMPL planner (PLANNERS)
    planning_time: float = 1.0           # [s] the planner's time budget
    velocity_scaling: float = 0.1        # (0, 1] fraction of the joint speed and acceleration limits;
    #                                      0.1 as MoveIt's default: a plan nobody asked to be fast is not
    planning_limits: str = ""            # MoveIt joint_limits.yaml the plan action times its plans to
    #                                      (commission's, beside its file); "" = the model's limits

    @classmethod
    def from_dict(cls, params: RawParams, cycle_rate: float, joint_names: Tuple[str, ...]
                  ) -> "MotionParams":
        """``cycle_rate``: the bus's (the timeouts cover two cycles); ``joint_names``: the plain
        names ``planning_limits`` must give limits of."""
        d = cls()
        planning_limits = _string(params, "planning_limits", d.planning_limits)
        if planning_limits:
            read_planning_limits(planning_limits, joint_names)
        out = cls(
            accept_timeout=_number(params, "accept_timeout", d.accept_timeout, 0.0, 60.0, lo_open=True),
            release_timeout=_number(params, "release_timeout", d.release_timeout, 0.0, 60.0, lo_open=True),
            motion_timeout_factor=_number(params, "motion_timeout_factor", d.motion_timeout_factor, 1.0, 100.0),
            motion_timeout_margin=_number(params, "motion_timeout_margin", d.motion_timeout_margin, 0.0, 600.0),
            stop_settle_time=_number(params, "stop_settle_time", d.stop_settle_time, 0.0, 5.0, lo_open=True),
            stop_timeout=_number(params, "stop_timeout", d.stop_timeout, 0.0, 600.0, lo_open=True),
            stream_smooth=_integer(params, "stream_smooth", d.stream_smooth, 0, 10),
            stream_path_tolerance=_number(params, "stream_path_tolerance", d.stream_path_tolerance, 0.0, 5.0),
            joint_command_timeout=_number(params, "joint_command_timeout", d.joint_command_timeout,
                                          0.0, 5.0, lo_open=True),
            planner_id=_string(params, "planner_id", d.planner_id, PLANNERS),
            planning_time=_number(params, "planning_time", d.planning_time, 0.0, 60.0, lo_open=True),
            velocity_scaling=_number(params, "velocity_scaling", d.velocity_scaling, 0.0, 1.0, lo_open=True),
            planning_limits=planning_limits,
        )
        _cycles("stop_settle_time", out.stop_settle_time, cycle_rate,
                ": the pose must be seen unchanged in two records")
        _cycles("joint_command_timeout", out.joint_command_timeout, cycle_rate,
                ": a command may wait a cycle for the bus and another for the controller")
        if out.stop_timeout <= out.stop_settle_time:
            raise ParamError("stop_timeout", out.stop_timeout, "must be longer than stop_settle_time "
                             "(%g s)" % out.stop_settle_time)
        return out


@dataclass(frozen=True)
class CheckParams:
    """Safety and model: the names, the workspace, the model, the collision checks, the model
    check against the controller."""

    # the model against the controller (protocols that report joints and pose: v2)
    model_check_position: float = 0.5    # [mm] the reported pose may differ this much from our FK of
    model_check_angle: float = 0.05      # [deg] the reported joints before the model is called off
    prefix: str = ""                     # of every link, joint and frame name of this robot (the
    #                                      URDF's xacro prefix); from_dict puts it in front of
    #                                      controller_joint_names and base_frame below
    workspace: Workspace = field(default_factory=Workspace)
    controller_joint_names: Tuple[str, ...] = DEFAULT_JOINT_NAMES
    tcp_offset: Tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)   # mm, deg in the flange frame
    model: str = ""                      # kinematics YAML (the layout of kinematics_vr006l.yaml, e.g.
    #                                      `calibrate fit --write`'s); "" = the package's model
    base_frame: str = "base"
    # collision checking (issue 27; doc/collision_scene.md)
    scene: str = ""                      # cell YAML of the objects around the arm; "" = none
    collision_padding: float = 0.01      # [m] every shape inflated by this for the verdict
    collision_check: bool = True         # check every path against the arm itself (SRDF) and the scene

    @staticmethod
    def plain_joint_names(params: RawParams) -> Tuple[str, ...]:
        """``controller_joint_names`` as given (without the prefix): 6 distinct names."""
        names = params.get("controller_joint_names", list(DEFAULT_JOINT_NAMES))
        if (not isinstance(names, (list, tuple)) or len(names) != 6
                or not all(isinstance(n, str) and n for n in names) or len(set(names)) != 6):
            raise ParamError("controller_joint_names", names, "expected 6 distinct joint names")
        return tuple(names)

    @classmethod
    def from_dict(cls, params: RawParams) -> "CheckParams":
        """``prefix`` is applied here, once: ``controller_joint_names`` and ``base_frame`` are the
        prefixed names the rest of the driver publishes and checks."""
        d = cls()
        names = cls.plain_joint_names(params)
        workspace = params.get("workspace", {})
        if not isinstance(workspace, Mapping):
            raise ParamError("workspace", workspace, "expected a mapping {x, y, z, angle}")
        try:
            workspace = Workspace.from_dict(workspace)
        except (VrDriverError, TypeError, ValueError) as exc:
            raise ParamError("workspace", dict(workspace), str(exc)) from None
        tcp = _vector(params, "tcp_offset", d.tcp_offset, 6)
        try:
            ControllerPose(*tcp)
        except VrDriverError as exc:
            raise ParamError("tcp_offset", list(tcp), str(exc)) from None
        base_frame = _string(params, "base_frame", d.base_frame)
        if not base_frame:
            raise ParamError("base_frame", base_frame, "must not be empty")
        prefix = _prefix(params, d.prefix)
        return cls(
            model_check_position=_number(params, "model_check_position", d.model_check_position, 0.0, 1000.0,
                                         lo_open=True),
            model_check_angle=_number(params, "model_check_angle", d.model_check_angle, 0.0, 180.0,
                                      lo_open=True),
            prefix=prefix,
            workspace=workspace,
            controller_joint_names=prefixed(prefix, names),
            tcp_offset=tcp,
            model=_model(params, d.model),
            base_frame=prefix + base_frame,
            scene=_existing_file(params, "scene", d.scene),
            collision_padding=_number(params, "collision_padding", d.collision_padding, 0.0, 1.0),
            collision_check=_boolean(params, "collision_check", d.collision_check),
        )


@dataclass(frozen=True)
class PublishParams:
    """What the node publishes, how often."""

    status_rate: float = 10.0
    joint_states_rate: float = 20.0
    diagnostics_period: float = 1.0
    io_states_rate: float = 2.0          # io_states at this rate besides on every change [Hz]
    publish_markers: bool = True

    @classmethod
    def from_dict(cls, params: RawParams) -> "PublishParams":
        d = cls()
        return cls(
            status_rate=_number(params, "status_rate", d.status_rate, 0.0, 1000.0, lo_open=True),
            joint_states_rate=_number(params, "joint_states_rate", d.joint_states_rate, 0.0, 1000.0,
                                      lo_open=True),
            diagnostics_period=_number(params, "diagnostics_period", d.diagnostics_period, 0.1, 60.0),
            io_states_rate=_number(params, "io_states_rate", d.io_states_rate, 0.0, 100.0, lo_open=True),
            publish_markers=_boolean(params, "publish_markers", d.publish_markers),
        )


#: DriverParams' sections: {attribute: its class}; each field of a section is also a flat,
#: read-only attribute of DriverParams (``params.port`` is ``params.link.port``) and a flat key of
#: the parameters (config/vr_driver.yaml): the sections are a code structure, the files stay flat
SECTIONS = {"link": LinkParams, "motion": MotionParams, "checks": CheckParams, "publishing": PublishParams}
_SECTION_OF = {f.name: section for section, kind in SECTIONS.items() for f in fields(kind)}


def _flat_attributes(cls: type) -> type:
    """Each field of a section as a read-only attribute of ``cls`` (``cls.port`` reads
    ``self.link.port``): one mechanism for the flat names, none written by hand."""
    for name, section in _SECTION_OF.items():
        if hasattr(cls, name):
            raise TypeError("%s.%s: a section field would hide the attribute" % (cls.__name__, name))
        setattr(cls, name, property(attrgetter(section + "." + name), doc="``%s.%s`` (read-only)" % (section, name)))
    return cls


@_flat_attributes
@dataclass(frozen=True, init=False)
class DriverParams:
    """Everything the driver reads at start (see config/vr_driver.yaml for the documentation): the
    sections (:data:`SECTIONS`), the G2 as commissioned (doc/commissioning.md: its measured
    behaviours, and where they came from). Built with the sections or with flat keywords
    (``DriverParams(stop_timeout=5.0)``, ``dataclasses.replace(params, scene="")``: each goes to
    its section); read flat (``params.stop_timeout``) or by section (``params.motion``)."""

    link: LinkParams
    motion: MotionParams
    checks: CheckParams
    publishing: PublishParams
    controller: ControllerFacts
    commissioning: Mapping[str, Any] = field(hash=False)   # date, identity, table: information

    def __init__(self, link: Optional[LinkParams] = None, motion: Optional[MotionParams] = None,
                 checks: Optional[CheckParams] = None, publishing: Optional[PublishParams] = None,
                 controller: Optional[ControllerFacts] = None,
                 commissioning: Optional[Mapping[str, Any]] = None, **flat: object) -> None:
        given = {"link": link, "motion": motion, "checks": checks, "publishing": publishing}
        changes: Dict[str, Dict[str, Any]] = {}
        for name, value in flat.items():
            if name not in _SECTION_OF:
                raise TypeError("DriverParams() got an unexpected keyword argument %r" % name)
            changes.setdefault(_SECTION_OF[name], {})[name] = value
        for section, kind in SECTIONS.items():
            value = given[section] or kind()
            object.__setattr__(self, section, replace(value, **changes.get(section, {})))
        object.__setattr__(self, "controller", controller or ControllerFacts())
        object.__setattr__(self, "commissioning", dict(commissioning or {}))

    @staticmethod
    def keys() -> Tuple[str, ...]:
        """Every parameter's flat key (config/vr_driver.yaml), sorted."""
        return tuple(sorted(list(_SECTION_OF) + ["controller", "commissioning"]))

    @classmethod
    def from_dict(cls, params: Optional[RawParams] = None) -> "DriverParams":
        """Validate ``params`` (flat keys; missing keys take the defaults; unknown keys are errors),
        section by section. ``controller_joint_names`` and ``base_frame`` in ``params`` are the plain
        names (:meth:`CheckParams.from_dict` applies ``prefix``)."""
        params = dict(params or {})
        known = cls.keys()
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise ParamError(unknown[0], params[unknown[0]], "unknown parameter (known: %s)" % ", ".join(known))
        link = LinkParams.from_dict(params)
        checks = CheckParams.from_dict(params)
        names = CheckParams.plain_joint_names(params)
        facts = ControllerFacts.from_dict(params.get("controller"), names)
        motion = MotionParams.from_dict(params, link.cycle_rate, names)
        commissioning = params.get("commissioning", {})
        if not isinstance(commissioning, Mapping):
            raise ParamError("commissioning", commissioning, "expected a mapping (the commissioning's date, "
                             "controller identity and table: information)")
        motion = replace(motion, stream_smooth=_stream_smooth(link.protocol, facts, motion.stream_smooth))
        return cls(link=link, motion=motion, checks=checks, publishing=PublishParams.from_dict(params),
                   controller=facts, commissioning=commissioning)

    def check_watchdog(self, watchdog_ms: Optional[int], source: str) -> None:
        """:meth:`LinkParams.check_watchdog`."""
        self.link.check_watchdog(watchdog_ms, source)

    @property
    def wire(self) -> "Any":
        """The controller protocol as one object (:class:`vr_driver.protocol.base.Protocol`); where
        the G2 does not take a target sent ahead (``controller/send_ahead`` other than accepted), a
        copy of it that sends one target per acknowledgement (``with_send_ahead``, offered by the
        protocols that send ahead of their slots)."""
        wire = _registry().get(self.protocol)
        if self.controller.send_ahead != "accepted" and wire.send_ahead > wire.look_ahead_slots:
            wire = wire.with_send_ahead(wire.look_ahead_slots)
        return wire

    def bus(self) -> "BusConfig":
        """The PROFIBUS bus configuration: the bus config file (or the package default) with
        this record's overrides applied, validated again by pyprofibus_vendor. Raises ParamError.
        The controller (``slave_address``) is ``slaves[0]``; the other slaves follow in the file's
        order (the I/O stations, :meth:`signal_map`)."""
        from pyprofibus_vendor.config import (BusConfig, ConfigError, ConfigValueError, default_robot_config,
                                              load_config)
        try:
            base = (load_config(self.bus_config) if self.bus_config
                    else default_robot_config(self.port or DEFAULT_PORT, slave_address=self.slave_address))
        except ConfigError as exc:
            raise ParamError("bus_config", self.bus_config, str(exc)) from None
        data: Dict[str, Any] = base.to_dict()
        wire = self.wire
        if not self.bus_config and wire.gsd_modules:
            for slave in data["slaves"]:
                slave.pop("cfg", None)
                slave["modules"] = list(wire.gsd_modules)
                slave["input_len"] = wire.input_length
                slave["output_len"] = wire.output_length
        data["cycle_rate_hz"] = self.cycle_rate
        if self.port:
            data["phy"]["device"] = self.port
        if self.baud is not None:
            data["baud"] = self.baud
        if self.master_address is not None:
            data["master_address"] = self.master_address
        slaves = [s for s in data["slaves"] if s["address"] == self.slave_address]
        if not slaves:
            raise ParamError("slave_address", self.slave_address, "no such slave in the bus config "
                             "(have %s)" % ", ".join(str(s["address"]) for s in data["slaves"]))
        if self.watchdog_ms is not None:
            slaves[0]["watchdog_ms"] = self.watchdog_ms or None
        # the controller first (the link supervisor drives slaves[0]); the others for the I/O line
        data["slaves"] = slaves + [s for s in data["slaves"] if s["address"] != self.slave_address]
        try:
            bus = BusConfig.from_dict(data)
        except ConfigError as exc:
            key = exc.key if isinstance(exc, ConfigValueError) else ""
            name, value = {"baud": ("baud", self.baud), "master_address": ("master_address", self.master_address),
                           "phy.device": ("port", self.port)}.get(key, ("bus_config", self.bus_config))
            raise ParamError(name, value, str(exc)) from None
        if bus.phy.type != "serial":
            raise ParamError("bus_config", self.bus_config, "the driver needs a serial PHY, not %r"
                             % bus.phy.type)
        slave = bus.slaves[0]
        self.check_watchdog(slave.watchdog_ms, "the bus config %s" % (self.bus_config or "(built in)")
                            if self.watchdog_ms is None else "watchdog_ms")
        if slave.input_len != wire.input_length or slave.output_len != wire.output_length:
            raise ParamError("bus_config", self.bus_config, "the controller protocol %s needs %d bytes "
                             "in / %d out; the configured modules give %d in / %d out"
                             % (self.protocol, wire.input_length, wire.output_length,
                                slave.input_len, slave.output_len))
        return bus

    def signal_map(self, bus: "BusConfig") -> Optional[SignalMap]:
        """The :class:`~vr_driver.io_signals.SignalMap` of ``io_signals`` checked against ``bus``
        (from :meth:`bus`), or None without one. Raises ParamError naming ``io_signals`` with the
        SignalMapError's words (a bad entry, a station that is not a slave of the bus config, or
        the controller's own address)."""
        if not self.io_signals:
            return None
        lengths = lengths_from_bus(bus)
        if self.wire.controller_io:     # the controller's own I/O: 16 inputs, 16 outputs in the records
            lengths[self.slave_address] = (CONTROLLER_IO_LENGTH, CONTROLLER_IO_LENGTH)
        try:
            signals = load_signal_map(self.io_signals, lengths)
        except SignalMapError as exc:
            raise ParamError("io_signals", self.io_signals, str(exc)) from None
        for station in signals.stations:
            if station.address != self.slave_address:
                continue
            if not self.wire.controller_io:
                raise ParamError("io_signals", self.io_signals, "station %r has address %d, the robot "
                                 "controller's (slave_address): the controller's own I/O needs a protocol "
                                 "that carries it (%s; %s's records have no room for it)"
                                 % (station.name, station.address, ", ".join(_io_protocols()), self.protocol))
            unsafe = [sig.name for sig in station.signals if sig.is_output and sig.safe]
            if unsafe:
                raise ParamError("io_signals", self.io_signals, "station %r (the controller's own I/O): "
                                 "the controller sets its outputs to 0 on a link loss, so every safe value "
                                 "must be 0 (%s)" % (station.name, ", ".join(unsafe)))
        return signals

