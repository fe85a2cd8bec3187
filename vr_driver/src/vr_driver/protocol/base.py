"""The protocol seam: one object per controller protocol, chosen once from the ``protocol``
parameter (:func:`vr_driver.protocol.get`), that says everything the rest of the stack may know of
the wire. ROS-free, no I/O.

Nothing outside ``vr_driver.protocol`` compares protocol names (``test_protocol_seam.py`` parses
every module and fails on such a comparison): code that depends on the protocol asks its object --
for a fact (record length, Chk_Cfg, resolution), a codec (encode / decode, the idle record), a
conversion (feedback -> joints), or a capability (``streams``: trajectories go out with their timing
and a look-ahead; ``reports_joints``: the feedback carries the joints; ``controller_io``: the records
carry the controller's own I/O words).

A protocol is both ends: the driver uses ``encode`` / ``decode_feedback`` / ``idle_record``, the
virtual controller ``decode_command`` / ``encode_feedback`` and the Chk_Cfg; both see the same
record length, so a card configured for another protocol refuses the master at Chk_Cfg.

The protocol object also names the code that runs it at each end: :meth:`Protocol.controller_program`
(the virtual G2's program), :meth:`Protocol.sequencer` (the driver's sequencer) and, for a streaming
protocol, :meth:`Protocol.stream_family` (how the driver makes its streams ready), each what that
end's package registered for it with :meth:`Protocol.implement` (the built-in protocols':
``vr_driver.controller.programs``, ``vr_driver.driver.sequencers``). A protocol nobody registered a
program or a sequencer for is refused in words -- it never runs on another protocol's code, however
alike their capabilities. Adding a protocol is one module (its Protocol subclass and records), one
registration (:func:`vr_driver.protocol.registry.register`), its controller program and its
sequencer (``vr_driver/test/test_toy_protocol.py`` does it).
"""
from __future__ import annotations

import math
import typing
from dataclasses import dataclass
from typing import Any, Dict, Optional, Sequence, Tuple, Union

from ..errors import ProtocolError
from ..poses import ControllerPose, MoveType, Workspace

__all__ = ["MoveCommand", "Protocol", "WireTarget", "framed_record", "rounded_pose"]


def rounded_pose(pose: ControllerPose, resolution: Tuple[float, float]) -> ControllerPose:
    """``pose`` with each field rounded half away from zero to ``resolution`` (mm for X Y Z, deg for
    Rx Ry Rz): what a Cartesian target on the wire carries (a pose rounded already stays as it is)."""
    mm, deg = resolution
    out = []
    for value, unit in zip(pose.as_tuple(), (mm, mm, mm, deg, deg, deg)):
        steps = math.floor(abs(value) / unit + 0.5)
        out.append(math.copysign(steps, value) * unit if steps else 0.0)
    return ControllerPose(*out)

#: each registered protocol's version byte by its name (vr_driver.protocol.registry keeps it), so
#: that a record of another protocol is named in the error
_VERSIONS: Dict[str, int] = {}
#: what the packages at the two ends registered for each protocol, by its name and the role
#: (:meth:`Protocol.implement`)
_IMPLEMENTATIONS: Dict[Tuple[str, str], Any] = {}
#: the roles, what implements them and where the built-in protocols' are registered
_ROLES = {
    "controller_program": ("controller program", "the virtual G2", "vr_driver.controller.programs"),
    "sequencer": ("sequencer", "the driver", "vr_driver.driver.sequencers"),
    "stream_family": ("stream family", "the driver's stream preparation", "vr_driver.driver.sequencers"),
}


def framed_record(data: Any, size: int, version: int, what: str) -> bytes:
    """``data`` as the bytes of a record of ``size`` bytes whose first byte is ``version``;
    ProtocolError naming ``what`` otherwise (the record's own integrity check comes after)."""
    try:
        raw = bytes(data)
    except (TypeError, ValueError) as exc:
        raise ProtocolError("%s record must be bytes, got %r" % (what, type(data).__name__)) from exc
    if len(raw) != size:
        raise ProtocolError("%s record must be %d bytes, got %d" % (what, size, len(raw)))
    if raw[0] != version:
        other = [name for name, known in _VERSIONS.items() if known == raw[0]]
        raise ProtocolError("%s record: version byte %d, expected %d (is the other end running %s?)"
                            % (what, raw[0], version, "protocol " + other[0] if other else "another protocol"))
    return raw


@dataclass(frozen=True)
class WireTarget:
    """One target of a stream as the driver hands it to a streaming protocol
    (:meth:`Protocol.stream_command`): the protocol puts on the wire what it carries of it (v2: the
    joints; a Cartesian protocol: the pose)."""

    seq: int                                  # 1..65535, consecutive within a stream
    joints: Tuple[float, ...]                 # rad, the controller's joint order: the planned point
    pose: Optional[ControllerPose]            # mm / deg: FK of ``joints`` (Cartesian protocols need it)
    speed: int                                # 0.1 % of the joint speed limits, 1..1000
    smooth: int                               # 0 (an exact stop) .. the protocol's largest level


class MoveCommand(typing.Protocol):
    """One wire target of a move (PTP / LIN / CIRC) as :meth:`Protocol.move_commands` gives it: what
    the rest of the stack reads of it (the pose it carries, a line for logs)."""

    @property
    def pose(self) -> ControllerPose: ...

    def describe(self) -> str: ...


def _qualname(value: Any) -> str:
    return "%s.%s" % (getattr(value, "__module__", "?"), getattr(value, "__qualname__", repr(value)))


class Protocol:
    """One controller protocol (subclassed once per protocol; a single instance each).

    Class attributes (facts of the wire):

    - ``name`` / ``version``: the ``protocol`` parameter's value / the version byte (v1 has none: 1);
    - ``record_length``: bytes each way (a protocol whose records differ sets ``input_length`` and
      ``output_length`` instead, and ``record_length`` 0);
    - ``gsd_modules``: the card's GSD modules (inputs first), or None for the bus config's default
      (the thesis' 14-byte card configuration);
    - ``chk_cfg``: the Chk_Cfg bytes of those modules, or None for the default;
    - ``streams``: a planner trajectory goes out as a stream of timed targets with a look-ahead
      (False: one target at a time, the arm stops at each: the v1 handshake);
    - ``joint_targets``: targets are joint angles (False: Cartesian poses the controller solves);
    - ``reports_joints``: the feedback carries the joints (False: only the pose; the driver solves
      the joints by IK);
    - ``controller_io``: the records carry the controller's general-purpose I/O (16 in, 16 out);
    - ``confirm_records``: the controller program acts on a record only after two equal telegrams
      (the default of the virtual controller: the protocols without an integrity check need it);
    - ``pose_resolution``: (mm, deg) of a reported pose and of a Cartesian target;
    - ``joint_resolution``: deg of a reported joint (None: the protocol reports no joints);
    - ``target_error``: rad, how far the arm's joints may land from a planned joint point the wire
      carries (rounding of a Cartesian target, solved again by the controller's IK), away from
      singularities: the scalar default path and goal tolerances are built on it
      (:attr:`default_goal_tolerance`); with the arm's kinematics a Cartesian protocol's are built
      on the same rule per configuration (:mod:`vr_driver.driver.joints.resolution`);
    - ``summary``: one line for logs and ``--help``.
    """

    name: str = ""
    version: int = 0
    record_length: int = 0
    gsd_modules: Optional[Tuple[str, ...]] = None
    chk_cfg: Optional[bytes] = None
    streams: bool = False
    joint_targets: bool = False
    reports_joints: bool = False
    controller_io: bool = False
    confirm_records: bool = False
    pose_resolution: Tuple[float, float] = (1.0, 1.0)
    joint_resolution: Optional[float] = None
    target_error: float = 0.0
    summary: str = ""

    @property
    def input_length(self) -> int:
        """Bytes controller -> master (the feedback: the master's DP inputs)."""
        return self.record_length

    @property
    def output_length(self) -> int:
        """Bytes master -> controller (the command: the master's DP outputs)."""
        return self.record_length

    # ------------------------------------------------------------------ tolerances
    #: rad: the least goal tolerance of a joint a goal leaves at 0 (what the stack promises a goal
    #: reaches, where the wire allows it)
    goal_tolerance_floor: float = math.radians(0.05)
    #: rad: what a joint's default path tolerance allows beyond its goal tolerance (the deviation the
    #: timing and the blending -- v1: the straight joint moves between its stop points -- add)
    path_allowance: float = math.radians(1.0)

    def goal_tolerance_for(self, wire_error: float) -> float:
        """rad: the default goal tolerance of a joint whose position the wire can put ``wire_error``
        [rad] off: twice that (the target's rounding, solved again by the controller, and the
        reported pose's), at least :attr:`goal_tolerance_floor`. The rule behind
        :attr:`default_goal_tolerance` (``wire_error`` = ``target_error``) and, per configuration,
        behind the Cartesian protocols' tolerances (:mod:`vr_driver.driver.joints.resolution`: the error
        there through the Jacobian)."""
        return max(self.goal_tolerance_floor, 2.0 * wire_error)

    def path_tolerance_for(self, wire_error: float) -> float:
        """rad: the default path tolerance for ``wire_error``: :meth:`goal_tolerance_for` plus
        :attr:`path_allowance`."""
        return self.goal_tolerance_for(wire_error) + self.path_allowance

    @property
    def default_goal_tolerance(self) -> float:
        """rad: the goal tolerance of a joint a FollowJointTrajectory goal leaves at 0, for a caller
        that has no kinematics (:meth:`goal_tolerance_for` of ``target_error``): a goal with empty
        tolerances never fails because of the wire's own resolution away from singularities. With
        the arm's kinematics the Cartesian protocols' defaults are per configuration instead
        (``validate(..., resolution=WireResolution.of(kin, wire))``)."""
        return self.goal_tolerance_for(self.target_error)

    @property
    def default_path_tolerance(self) -> float:
        """rad: the path tolerance of a joint a goal leaves at 0 (:meth:`path_tolerance_for` of
        ``target_error``): 1 deg beyond the goal tolerance."""
        return self.path_tolerance_for(self.target_error)

    # ------------------------------------------------------------------ driver side
    def encode(self, command: Any, byte_order: Any = "little") -> bytes:
        """The bytes of a master record (a command of this protocol)."""
        raise NotImplementedError

    def idle_record(self, byte_order: Any = "little") -> bytes:
        """The master record that asks nothing of the controller (sent while nothing moves and at
        every (re)connection: it arms the controller program)."""
        raise NotImplementedError

    def idle_command(self) -> Any:
        """The command object of :meth:`idle_record`."""
        raise NotImplementedError

    def move_commands(self, move_type: Union[MoveType, str], target: ControllerPose, via: Optional[ControllerPose] = None,
                      workspace: Optional[Workspace] = None) -> Tuple[MoveCommand, ...]:
        """The wire targets of a move (``move_type`` PTP / LIN / CIRC, a MoveType or its name), in
        sending order, validated and rounded as the wire carries them: the driver plans the move to
        exactly these (PoseError / ProtocolError naming what is wrong; ``workspace``: the targets
        inside its box). Every built-in protocol plans a move to the thesis' handshake targets
        (whole mm / deg; CIRC: the via point, then the end): v1 sends them one at a time, a
        streaming protocol the planned path's samples up to the last one
        (:func:`vr_driver.protocol.v1.move_targets`)."""
        raise NotImplementedError

    def stop_record(self, record: bytes, byte_order: Any = "little") -> bytes:
        """The master record that stops whatever ``record`` (the one on the wire now) set going: what
        the bus process sends when the driver dies (vr_driver.bus.process). A streaming protocol's
        STOP; a handshake protocol overrides it (v1: the same target with the stop flag)."""
        return self.encode(self.stream_command((), stop=True), byte_order)

    def decode_feedback(self, data: Any, byte_order: Any = "little") -> Any:
        """A controller record as this protocol's feedback object; ProtocolError (with the reason)
        for bytes that are not one."""
        raise NotImplementedError

    def program_speed(self, move_type: Union[MoveType, str], movep: float, movel: float) -> Optional[float]:
        """[mm/s] the TCP speed the controller's program runs a target of ``move_type`` (PTP / LIN /
        CIRC) at, whatever a plan's timing, given the program's speeds [m/min]: ``movep`` for a PTP,
        ``movel`` for a LIN or a CIRC (``controller/program_speed`` / ``program_path_speed``); None
        where the protocol runs a plan's own timing (a streaming protocol). v1 (MOVEP / MOVEL /
        MOVEC: :func:`vr_driver.protocol.v1.program_speed`)."""
        return None

    def feedback_joints(self, feedback: Any) -> Optional[Tuple[float, ...]]:
        """The joints [rad] a feedback record reports, or None where the protocol reports only the
        pose (the driver then solves them)."""
        return None

    # ------------------------------------------------------------------ streaming protocols
    #: targets a streaming protocol's record offers at once (v2: 2 slots; 0: not a streaming protocol)
    look_ahead_slots: int = 0
    #: how many targets from the first one the controller has not acknowledged yet the master may
    #: put on the wire (>= look_ahead_slots). A controller acknowledges a record one bus cycle after
    #: it arrived (its reply to the same telegram carries the older feedback), so a one-slot record
    #: that waited for the acknowledgement would bring one target every two cycles; with 2, the
    #: master sends the next target in the very next cycle. The controller takes only the target
    #: after the last one it took: one further ahead (sent before the acknowledgement of the one
    #: before it, which the controller had no room for) waits -- neither taken nor refused -- and the
    #: master goes back to the first unacknowledged target (exactly once either way).
    send_ahead: int = 0
    #: a record that changed goes out at once, in an extra bus cycle (v2: its controller acts at the
    #: first telegram; False: one record per bus cycle, so that the controller's program loop reads
    #: each record the master sends ahead before the next one replaces it)
    send_changes_at_once: bool = False

    def stream_command(self, targets: Sequence[WireTarget], start: bool = False, stop: bool = False,
                       outputs: int = 0) -> Any:
        """A streaming protocol's command: STOP (no target), or up to ``look_ahead_slots`` targets
        (the first not yet taken by the controller, then the ones after it; ``start``: the first
        begins a new stream), and the controller's outputs where the protocol carries them.
        ProtocolError for a target the wire cannot carry."""
        raise NotImplementedError

    def feedback_heartbeat(self, feedback: Any) -> Optional[int]:
        """The program's loop counter in a feedback record (+1 every program loop, modulo 65536),
        or None where the protocol has none (v1). It dates the record
        (:mod:`vr_driver.driver.link.record_clock`)."""
        return None

    # ------------------------------------------------------------------ controller side
    def decode_command(self, data: Any, byte_order: Any = "little") -> Any:
        """A master record as this protocol's command object (ProtocolError otherwise)."""
        raise NotImplementedError

    def encode_feedback(self, feedback: Any, byte_order: Any = "little") -> bytes:
        return feedback.encode(byte_order) if self.byte_order_matters else feedback.encode()

    #: the records' words follow the ``byte_order`` parameter (v1); False: fixed little-endian
    byte_order_matters: bool = False

    def wire_pose(self, pose: ControllerPose) -> ControllerPose:
        """``pose`` as a Cartesian target of this protocol carries it: each field rounded half away
        from zero to ``pose_resolution`` (mm for X Y Z, deg for Rx Ry Rz), the controller's view."""
        return rounded_pose(pose, self.pose_resolution)

    # ------------------------------------------------------------------ the code at each end
    def implement(self, *, controller_program: Any = None, sequencer: Any = None,
                  stream_family: Any = None) -> None:
        """Register the code that runs this protocol: ``controller_program``, the virtual G2's program
        class (a :class:`~vr_driver.controller.session.SessionProgram` with ``make_arm`` /
        ``from_options``), ``sequencer``, the driver's sequencer class, and / or ``stream_family``
        (a streaming protocol), the class that makes the driver's streams ready to send for it
        (:mod:`vr_driver.driver.checks.stream_prep`: joint targets sent as planned, or Cartesian targets
        solved as the controller will). Called by the package of that end (never by this package,
        which imports neither). Registering the same class again is harmless; another class for a
        role already taken is a ProtocolError (a protocol runs on one program, never silently on the
        last one registered)."""
        for role, value in (("controller_program", controller_program), ("sequencer", sequencer),
                            ("stream_family", stream_family)):
            if value is None:
                continue
            key = (self.name, role)
            known = _IMPLEMENTATIONS.get(key)
            if known is not None and known is not value:
                raise ProtocolError("protocol %s already has a %s (%s), not registering %s"
                                    % (self.name, _ROLES[role][0], _qualname(known), _qualname(value)))
            _IMPLEMENTATIONS[key] = value

    def controller_program(self) -> Any:
        """The class of the virtual G2's program for this protocol (registered with
        :meth:`implement`); ProtocolError in words when there is none -- never another
        protocol's."""
        return self._implementation("controller_program")

    def sequencer(self) -> Any:
        """The class of the driver's sequencer for this protocol (registered with :meth:`implement`:
        v1's handshake sequencer, the stream sequencer); ProtocolError in words when there is none."""
        return self._implementation("sequencer")

    def stream_family(self) -> Any:
        """The class of the driver's stream preparation for this streaming protocol (registered with
        :meth:`implement`: joint or Cartesian streams); ProtocolError in words when there is none --
        never the family its capabilities look like."""
        return self._implementation("stream_family")

    def _implementation(self, role: str) -> Any:
        try:
            return _IMPLEMENTATIONS[(self.name, role)]
        except KeyError:
            what, end, where = _ROLES[role]
            raise ProtocolError("protocol %s has no %s registered: %s cannot run it (its %s registers with "
                                "protocol.implement(%s=...); the built-in protocols' are in %s)"
                                % (self.name, what, end, what, role, where)) from None

    def describe(self) -> str:
        return "%s (%d bytes each way): %s" % (self.name, self.record_length, self.summary)

    def __repr__(self) -> str:
        return "<protocol %s>" % self.name
