"""The link side of a virtual G2 program, shared by every protocol's program (v1
:class:`~vr_driver.controller.program_v1.ControllerProgramV1`, v2
:class:`~vr_driver.controller.program_v2.ControllerProgramV2`, v3
:class:`~vr_driver.controller.program_v3.ControllerProgramV3`). ROS-free.

:class:`SessionProgram` hooks a :class:`~pyprofibus_vendor.DpSlave` and gives each program loop the
master's command of the current Data_Exchange session (``None``: no command), with the rules both
protocols share (doc/controller_program.md, §4 rule 9 and §9.3 rules 5 and 7):

- A *session* starts each time the slave enters Data_Exchange. Only a record the master sent in the
  current session counts; outside Data_Exchange, and in a new session before the master's first
  Data_Exchange, there is no command.
- Two-telegram rule (``confirm_records``): a record counts only once it arrived unchanged in two
  consecutive Data_Exchange telegrams of the session.
- Disarmed at start and after every link loss: a request counts only after an *idle* record
  (v1: the flag not 1; v2: both slots empty) of the session arrived -- it arms the program when it
  arrives, even between two loops. A request seen while disarmed is *stale*.
- Link loss (the DP watchdog expired, or the slave left Data_Exchange / was re-parameterised, also
  between two loops): the subclass stops the arm, at the watchdog deadline when the watchdog
  expired, so the arm never moves longer than the watchdog time after the master's last telegram.
- A record that does not decode is no command, counted in :attr:`bad_records` (a warning once per
  distinct record).

Exactly once across a reset (doc/controller_program.md §4 rule 10, §9.3 rule 5, §10.4 rule 3): after
the card's watchdog or a new Set_Prm / Chk_Cfg the program takes nothing it could have read before
the reset; it takes a new command only after an idle record read in the new session. How a program
knows that a reset happened is an assumption about the G2 (``data_exchange_bit``):

- ``data_exchange_bit=True`` (default): the program reads a status of its card that says "in
  Data_Exchange, with the master's record of this session" -- set at the master's first
  Data_Exchange telegram, cleared when the card leaves Data_Exchange, a loss kept until the next
  program loop has read it. The virtual program reads it from the slave's session (its state hooks):
  a loss between two loops is seen, and the card's safe image is never taken for a record.
- ``data_exchange_bit=False``: the program reads nothing but its input bytes as the card holds them
  at each loop (the two-telegram rule: read equal in two loops). The card writes its safe image
  (all zero) into them when it leaves Data_Exchange, and the program sees a reset only there: where the safe image is no record of the protocol (v2, v3: version byte 0), a
  loop that reads it is a link loss (the arm stops, the program disarms); where it reads as the
  idle record (v1: flag 0, all zero) the program cannot tell a reset at all -- it releases a held
  DONE on it like on the master's flag 0, so exactly once across a reset then rests on the master,
  whose first record of every session is the idle record (driver/link/link.py). A reset over before any
  loop read the safe image is not seen either; the records go on as if there was none.

Two more assumptions about the G2's program loop live here, shared by every protocol
(doc/controller_program.md §10.9):

- ``loop_blocks_during_move`` (default False: the loop keeps running while the arm moves): True is
  a G2 whose MOVE line blocks the program until the motion has ended (§5 "Moves block"). While a
  motion the program started runs, no loop runs: no record is read (not even a STOP or a link loss:
  they are seen in the first loop after the arm came to rest), the feedback is not written (the
  last record stays on the bus, its heartbeat frozen) and nothing new reaches the arm; the card's
  own watchdog goes on (:meth:`SessionProgram.suspended`).
- ``unreachable`` (:class:`Unreachable`, default ``skip``): a target the program cannot solve or
  plan is refused and the program goes on (v1 REJECTED, v2 / v3 code UNREACHABLE), or
  (``alarm_halt``) the G2 raises an alarm and halts the program: the arm stops at once (the alarm
  is the arm's error), the targets taken are dropped, and no loop runs any more -- the record last
  written stays on the bus (v1: BUSY, written before the MOVE; v2 / v3: the record of the loop
  before). Clearing the error (the operator resets the alarm and starts the program again)
  restarts the program as at its start: disarmed, the handshake / stream state of a fresh program.
"""
from __future__ import annotations

import enum
import logging
import threading
from typing import Any, Callable, Dict, Optional, Tuple

from pyprofibus_vendor.dp_slave import DpSlave, SlaveState

from .. import validate
from ..errors import ProtocolError, VrDriverError
from ..protocol.common import StatusBits

__all__ = ["SessionProgram", "Unreachable", "arm_status_bits"]

log = logging.getLogger(__name__)


class Unreachable(enum.Enum):
    """What the G2 does with a target it cannot reach (an assumption, doc/controller_program.md §5
    notes, §10.9): ``skip`` -- the program finds out before the MOVE, refuses it and goes on (the
    default); ``alarm_halt`` -- the G2 raises an alarm and halts the program."""

    SKIP = "skip"
    ALARM_HALT = "alarm_halt"

    parse = validate.choice_parser(VrDriverError, "unreachable must be {words}, got {value!r}")


def arm_status_bits(arm: Any) -> StatusBits:
    """Status bits 0-4 of an arm (SimArm or SimStreamArm): drives, e-stop, error, in motion, and
    PROGRAM_RUNNING (the program writes every record it sends)."""
    bits = StatusBits.PROGRAM_RUNNING
    if arm.drives_powered:
        bits |= StatusBits.DRIVES_POWERED
    if arm.estop:
        bits |= StatusBits.ESTOP
    if arm.error is not None:
        bits |= StatusBits.ERROR
    if arm.moving:
        bits |= StatusBits.IN_MOTION
    return bits


class SessionProgram:
    """Session, two-telegram rule, arming and link loss on one DP slave (see the module docstring),
    for a program moving ``arm`` (it needs ``last_step_time``: a stop never goes back in time).

    Subclasses define :meth:`decode_record` (raw bytes -> command, ProtocolError when it does not
    decode), :meth:`is_idle_command` (the command arms the program) and :meth:`on_link_lost` (stop
    the arm; called from :meth:`read_command`), and call :meth:`read_command` at the start of each
    program loop -- after :meth:`suspended`, which says whether the loop runs at all (a MOVE blocking
    it, or the program halted by an alarm); :meth:`advance_suspended`, :meth:`on_halt` and
    :meth:`on_restart` are their hooks for that.
    """

    def __init__(self, slave: DpSlave, arm: Any, *, confirm_records: bool = False,
                 data_exchange_bit: bool = True, loop_blocks_during_move: bool = False,
                 unreachable: Any = Unreachable.SKIP) -> None:
        if not isinstance(data_exchange_bit, bool):
            raise VrDriverError("data_exchange_bit must be True or False, got %r" % (data_exchange_bit,))
        if not isinstance(loop_blocks_during_move, bool):
            raise VrDriverError("loop_blocks_during_move must be True or False, got %r" % (loop_blocks_during_move,))
        self.slave = slave
        self.arm = arm
        self.confirm_records = confirm_records
        #: the program reads its card's Data_Exchange status (True) or only its input bytes (False)
        self.data_exchange_bit = data_exchange_bit
        #: a MOVE blocks the program loop until the motion ended (module docstring)
        self.loop_blocks_during_move = loop_blocks_during_move
        #: an unreachable target is refused (skip) or raises an alarm that halts the program
        self.unreachable = Unreachable.parse(unreachable)
        #: the alarm that halted the program (None: it runs)
        self.halted: Optional[str] = None
        self.alarms = 0
        self.blocked_loops = 0          # loops that did not run: a MOVE blocked the program
        self.loops = 0
        self.bad_records = 0
        self.link_losses = 0
        self.last_command: Any = None
        self._armed = False
        self._active_session: Optional[int] = None   # the session the last loop ran in
        self._deadline: Optional[float] = None      # watchdog deadline seen at the last loop
        self._expiries = slave.counters.watchdog_expiries
        self._bad_raw: Optional[bytes] = None
        # written by the slave's hooks (the server thread), read by read_command()
        self._io_lock = threading.Lock()
        self._session = 1 if slave.state is SlaveState.DATA_EXCH else 0
        self._record_of_session: Optional[bytes] = None
        self._last_arrival: Optional[bytes] = None     # the session's latest telegram (unconfirmed)
        self._zero_seen = False                         # a (confirmed) idle record came
        self._left_reason = ""
        # data_exchange_bit=False: the input bytes read at the last loop, the record they confirmed
        # (read equal in two loops, or at once without confirm_records), whether the link was up
        self._last_read: Optional[bytes] = None
        self._view: Optional[bytes] = None
        self._bytes_link_up = False
        self._safe_is_record = self._command_of(bytes(slave.output_size)) is not None
        self._chained_outputs = slave.on_outputs
        self._chained_state = slave.on_state_change
        slave.on_outputs = self._on_outputs
        slave.on_state_change = self._on_state_change

    # ------------------------------------------------------------------- built by the virtual G2
    #: the simulated arm class this program moves (the virtual G2 refuses another)
    ARM_TYPE: type = object

    @classmethod
    def make_arm(cls, kinematics: Any, options: Any, clock: Callable[[], float]) -> Any:
        """The simulated arm this program moves, from the virtual G2's validated options (a
        :class:`~vr_driver.controller.options.SimOptions`) and the arm's ``kinematics`` (None: the
        model's). VrDriverError for an initial pose it cannot take."""
        raise NotImplementedError

    @classmethod
    def from_options(cls, slave: DpSlave, arm: Any, options: Any, *, execution_log: Any,
                     confirm_records: bool, kinematics: Any = None) -> "SessionProgram":
        """This program on ``slave`` and ``arm`` with the virtual G2's options (``kinematics``: the
        controller's own, for a program that solves Cartesian targets)."""
        raise NotImplementedError

    @staticmethod
    def loop_options(options: Any) -> Dict[str, Any]:
        """The options of the link side and the loop every program takes (this class's keyword
        arguments) from the virtual G2's options."""
        return dict(data_exchange_bit=options.data_exchange_bit,
                    loop_blocks_during_move=options.loop_blocks_during_move, unreachable=options.unreachable)

    # ------------------------------------------------------------------- subclass interface
    def decode_record(self, raw: bytes) -> Any:
        raise NotImplementedError

    def is_idle_command(self, command: Any) -> bool:
        raise NotImplementedError

    def on_link_lost(self, why: str, stop_time: float) -> None:
        raise NotImplementedError

    def advance_suspended(self, now: float) -> None:
        """Advance the arm to ``now`` while the loop does not run (the MOVE blocking it goes on; the
        subclass keeps what the arm reports for the next loop that runs)."""
        raise NotImplementedError

    def on_halt(self, reason: str, now: float) -> None:
        """The program halted by an alarm (the arm's error is set and has stopped it): log what
        ended."""

    def on_restart(self, now: float) -> None:
        """The alarm was cleared and the program starts again: reset its state as at its start."""

    # ------------------------------------------------------------------------- the loop's life
    def suspended(self, now: float) -> bool:
        """Whether the program loop does not run at ``now``: halted by an alarm whose error is still
        set, or (``loop_blocks_during_move``) a motion it started still runs. The arm advances
        either way and the card's own watchdog is served; nothing is read or written. A halted
        program whose error was cleared restarts here (:meth:`on_restart`) and runs this loop."""
        if self.halted is not None:
            if self.arm.error is not None:
                self.slave.step(now)
                self.advance_suspended(now)
                return True
            self._restart(now)
            return False
        if self.loop_blocks_during_move and self.arm.moving:
            self.slave.step(now)
            self.advance_suspended(now)
            if self.arm.moving:
                self.blocked_loops += 1
                return True
        return False

    def halt(self, reason: str, now: float) -> None:
        """``unreachable`` = alarm_halt: the G2 raises an alarm and halts the program. The alarm is
        the arm's error (it stops the arm at once and shows in the status bits of a record written
        after the restart); no loop runs until it is cleared."""
        self.halted = reason
        self.alarms += 1
        log.error("alarm: %s -- the program halted (clear the error to restart it)", reason)
        self.arm.set_error("alarm: %s" % reason, now)
        self.on_halt(reason, now)

    def _restart(self, now: float) -> None:
        log.warning("alarm cleared: the program starts again (disarmed) after: %s", self.halted)
        self.halted = None
        self._armed = False
        with self._io_lock:
            self._zero_seen = False         # armed only by an idle record read after the restart
        self._view = None
        self._last_read = None
        self.on_restart(now)

    # ------------------------------------------------------------------------- slave hooks
    def _on_outputs(self, data: bytes) -> None:
        with self._io_lock:
            if self.slave.state is SlaveState.DATA_EXCH:     # not the safe image of a leaving slave
                record = bytes(data)
                if not self.confirm_records or record == self._last_arrival:
                    self._record_of_session = record
                    if not self._zero_seen and self._idle_record(record):
                        self._zero_seen = True      # arms the program, even between two loops
                self._last_arrival = record
        if self._chained_outputs is not None:
            self._chained_outputs(data)

    def _on_state_change(self, old: SlaveState, new: SlaveState, reason: str) -> None:
        with self._io_lock:
            if new is SlaveState.DATA_EXCH:
                self._session += 1
            if old is SlaveState.DATA_EXCH:
                self._left_reason = reason
            self._record_of_session = None
            self._last_arrival = None
            self._zero_seen = False
        if self._chained_state is not None:
            self._chained_state(old, new, reason)

    def _command_of(self, record: bytes) -> Optional[Any]:
        """The program's command in ``record``, None when it is no valid record."""
        try:
            return self.decode_record(record)
        except ProtocolError:
            return None

    def _idle_record(self, record: bytes) -> bool:
        command = self._command_of(record)
        return command is not None and self.is_idle_command(command)

    # ---------------------------------------------------------------------------- read-outs
    @property
    def connected(self) -> bool:
        """True while the link was up at the last loop: the slave in Data_Exchange
        (``data_exchange_bit``), else a record in the input bytes that is not the card's safe image."""
        if not self.data_exchange_bit:
            return self._bytes_link_up
        return self._active_session is not None

    @property
    def armed(self) -> bool:
        """True once an idle record was seen in the current session."""
        return self._armed

    @property
    def sees_resets(self) -> bool:
        """Whether this program can tell that its card was reset (watchdog, new Set_Prm): with the
        card's Data_Exchange status always; from its input bytes only where the card's safe image
        (all zero) is no record of the protocol (v2, v3; not v1, whose idle record it is)."""
        return self.data_exchange_bit or not self._safe_is_record

    # ------------------------------------------------------------------------------ the loop
    def read_command(self, now: float) -> Tuple[Any, bool]:
        """The start of a program loop at ``now``: expire the watchdog, handle a link loss (calls
        :meth:`on_link_lost`), arm, and decode the session's record. Returns ``(command, stale)``:
        the command (None: none, or it did not decode) and whether it is a request that came while
        the program was disarmed."""
        self.loops += 1
        if not self.data_exchange_bit:
            return self._read_bytes_only(now)
        deadline = self.slave.next_deadline()
        self.slave.step(now)                        # expire the watchdog here, not a poll later
        connected = self.slave.state is SlaveState.DATA_EXCH
        with self._io_lock:
            session, raw, left_reason = self._session, self._record_of_session, self._left_reason
            zero_seen = self._zero_seen
        if self._active_session is not None and (not connected or session != self._active_session):
            self._link_lost(now, deadline, left_reason)
        if connected and zero_seen and not self._armed:
            self._armed = True          # an idle record of this session arrived (maybe between loops)
        self._active_session = session if connected else None
        self._deadline = self.slave.next_deadline() if connected else None
        command = self._decode(raw) if connected and raw is not None else None
        return self._arm(command)

    def _read_bytes_only(self, now: float) -> Tuple[Any, bool]:
        """:meth:`read_command` of a program that reads nothing but its input bytes
        (``data_exchange_bit=False``), as the card holds them at this loop (the master's last
        telegram, or the card's safe image). The two-telegram rule becomes "read equal in two
        loops" (what such a program can check). The safe image (all zero), where it is no record of
        the protocol, is a link loss when it first shows; a record arms / is stale as with the bit."""
        self.slave.step(now)                        # the card's own watchdog (not the program's doing)
        read = bytes(self.slave.outputs)
        if not self.confirm_records or read == self._last_read:
            self._view = read
        self._last_read = read
        raw = self._view
        if raw is None:
            self.last_command = None
            return None, False
        if not self._safe_is_record and not any(raw):
            if self._bytes_link_up:
                self._bytes_link_up = False
                self.link_losses += 1
                self._armed = False
                why = "link to the master lost (the card's safe image in the inputs: watchdog or new Set_Prm)"
                log.warning("%s: stopping the arm, resetting the program", why)
                self.on_link_lost(why, max(now, self.arm.last_step_time))
            self.last_command = None
            return None, False
        command = self._decode(raw)
        if command is not None:
            self._bytes_link_up = True
        return self._arm(command)

    def _arm(self, command: Any) -> Tuple[Any, bool]:
        """Arm on an idle record; a request while disarmed is stale. Returns ``(command, stale)``."""
        self.last_command = command
        stale = False
        if command is not None and not self._armed:
            if self.is_idle_command(command):
                self._armed = True
            else:
                stale = True                        # raised before we saw an idle record
        return command, stale

    def _decode(self, raw: bytes) -> Any:
        try:
            command = self.decode_record(raw)
        except ProtocolError as exc:
            self.bad_records += 1
            if raw != self._bad_raw:               # once per distinct record, not every loop
                log.warning("ignoring the master's record %s: %s", raw.hex(" "), exc)
            self._bad_raw = raw
            return None
        self._bad_raw = None
        return command

    def _link_lost(self, now: float, deadline: Optional[float], left_reason: str) -> None:
        self.link_losses += 1
        self._armed = False
        expired = self.slave.counters.watchdog_expiries != self._expiries
        self._expiries = self.slave.counters.watchdog_expiries
        # the deadline seen now, or the one of the last loop if the server thread expired it first
        if deadline is None:
            deadline = self._deadline
        stop_time = now
        if expired and deadline is not None:
            stop_time = min(now, max(deadline, self.arm.last_step_time))
        why = "DP watchdog expired (master silent)" if expired else \
            "link to the master lost (slave left Data_Exchange: %s)" % (left_reason or "unknown reason")
        log.warning("%s: stopping the arm, resetting the program", why)
        self.on_link_lost(why, stop_time)
