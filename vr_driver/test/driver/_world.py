"""A whole driver world in one thread with a fake clock: the stepped DriverCore (link supervisor,
sequencer), our DP master, the in-memory link, the virtual controller's DP slave, its program and
the simulated arm. No pty, no threads, no sleeps: time moves only when the world moves it, so every
run is the same run.

- :class:`FakeClock`: the one clock of the world (seconds).
- :class:`SteppedLink`: a :class:`~pyprofibus_vendor.dp_slave.SlaveLink` (the slave answers each
  telegram synchronously) on which waiting costs fake time: ``recv(timeout)`` with nothing to read
  moves the clock on by ``timeout`` (nothing else could arrive meanwhile); :attr:`cut` drops every
  telegram both ways (a pulled cable).
- :class:`World`: :meth:`World.tick` runs the next due event -- a controller program loop (every
  ``loop_period``) or a driver bus iteration (every bus period, unless :attr:`World.frozen`) and
  the driver's waiting planning tasks. :meth:`World.run_until` ticks until a condition holds.
"""
from __future__ import annotations

from typing import Any, Callable, Dict, List, Optional, Tuple

from pyprofibus_vendor.dp_slave import SlaveLink

from vr_driver.controller.program_v1 import ControllerProgramV1 as ControllerProgram
from vr_driver.controller.virtual_controller import robot_slave
from vr_driver.controller.program_v2 import ControllerProgramV2
from vr_driver.controller.program_v3 import ControllerProgramV3
from vr_driver.controller.stream_arm import SimStreamArm
from vr_driver.driver import DriverCore, DriverStatus, MoveJob
from vr_driver.params import DriverParams
from vr_driver.poses import HOME_POSE
from vr_driver.controller.arm import ExecutionLog, SimArm


class FakeClock:
    def __init__(self, start: float = 1000.0) -> None:
        self.t = start

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        assert dt >= 0.0
        self.t += dt


class SteppedLink(SlaveLink):
    wait_when_empty = False

    def __init__(self, slave, clock: FakeClock) -> None:
        super().__init__(slave)
        self.clock = clock
        self.cut = False
        self.telegrams = 0
        self.stall_next_read = 0.0     # the next read with data returns this much later (a freeze)

    def send(self, data: bytes) -> None:
        self.telegrams += 1
        if not self.cut:
            super().send(data)

    def recv(self, max_bytes: int = 4096, timeout: Optional[float] = 0.0) -> bytes:
        data = super().recv(max_bytes, 0.0)
        if not data and timeout:
            self.clock.advance(timeout)
        if data and self.stall_next_read:
            self.clock.advance(self.stall_next_read)     # the reply waited in the buffer
            self.stall_next_read = 0.0
        return data


#: fast, valid driver settings for the world (20 Hz bus as the default launch)
WORLD_PARAMS: Dict[str, Any] = {
    "port": "world", "baud": 19200, "cycle_rate": 20.0, "link_timeout": 0.5, "watchdog_ms": 300,
    "accept_timeout": 1.0, "reconnect_period": 0.5,
}


class World:
    def __init__(self, kin, params: Optional[Dict[str, Any]] = None, *, speed_factor: float = 1.0,
                 brake_time: float = 0.3, initial_pose: Any = HOME_POSE, loop_period: float = 0.01,
                 planner=None, protocol: str = "v1", interpreter_lookahead: int = 1,
                 controller_kin=None, ramp_time: Optional[float] = None,
                 program_speeds: Optional[Tuple[float, float]] = None) -> None:
        """``kin``: the driver's model (None: the driver builds it from ``params``, e.g. ``model``;
        then the controller needs ``controller_kin``). ``program_speeds``: v1, the program's MOVEP and
        MOVEL / MOVEC speeds [m/min] (None: the arm's full speed, as the stepped tests were written)."""
        if kin is None and controller_kin is None:
            raise ValueError("World: kin=None needs controller_kin")
        self.clock = FakeClock()
        self.kin = kin
        self.protocol = protocol
        self.streams = protocol in ("v2", "v3")
        self.slave = robot_slave(clock=self.clock, protocol=protocol)
        self.log = ExecutionLog()
        extra = {} if ramp_time is None else {"ramp_time": ramp_time}
        if protocol == "v3":
            self.arm = SimStreamArm(controller_kin or kin, speed_factor=speed_factor, initial_pose=initial_pose,
                                    clock=self.clock, brake_time=brake_time, look_ahead=interpreter_lookahead,
                                    **extra)
            self.program = ControllerProgramV3(self.slave, self.arm, kinematics=controller_kin or kin,
                                               execution_log=self.log)
        elif protocol == "v2":
            self.arm = SimStreamArm(controller_kin or kin, speed_factor=speed_factor, initial_pose=initial_pose,
                                    clock=self.clock, brake_time=brake_time, **extra)
            self.program = ControllerProgramV2(self.slave, self.arm, execution_log=self.log)
        else:
            self.arm = SimArm(kin or controller_kin, planner, speed_factor=speed_factor, initial_pose=initial_pose,
                              clock=self.clock, brake_time=brake_time, program_speeds=program_speeds)
            self.program = ControllerProgram(self.slave, self.arm, execution_log=self.log,
                                             confirm_records=True)
        self.link = SteppedLink(self.slave, self.clock)
        self.params = DriverParams.from_dict(dict(WORLD_PARAMS, protocol=protocol, **(params or {})))
        self.opened = 0
        self.open_error: Optional[Exception] = None
        self.core = DriverCore(self.params, kinematics=kin, previewer=planner, clock=self.clock,
                               open_link=self._open)
        self.kin = self.core.kin
        self.bus_period = 1.0 / self.params.cycle_rate
        self.loop_period = loop_period
        self.next_bus = self.clock.t
        self.next_loop = self.clock.t
        self.frozen = False            # True: the driver's bus loop does not run (a stopped process)
        self.statuses: List[DriverStatus] = []
        self.core.add_listener(self.statuses.append)
        self.bus_times: List[float] = []

    def _open(self, device: str, baud: int):
        if self.open_error is not None:
            raise self.open_error
        self.opened += 1
        return self.link

    # ------------------------------------------------------------------ time
    @property
    def now(self) -> float:
        return self.clock.t

    def tick(self) -> None:
        due = self.next_loop if self.frozen else min(self.next_loop, self.next_bus)
        if due > self.clock.t:
            self.clock.t = due
        if self.clock.t >= self.next_loop:
            self.program.step(self.clock.t)
            self.next_loop = max(self.next_loop + self.loop_period, self.clock.t)
        if not self.frozen and self.clock.t >= self.next_bus:
            self.bus_times.append(self.clock.t)
            self.core.spin_once()
            self.core.run_planning()
            self.next_bus = self.core.next_cycle(self.clock.t, max(self.next_bus + self.bus_period,
                                                                   self.clock.t))

    def run_until(self, predicate: Callable[[], bool], timeout: float, what: str = "") -> float:
        """Tick until ``predicate()`` holds; AssertionError after ``timeout`` of world time.
        Returns the world time it took."""
        start = self.clock.t
        while not predicate():
            if self.clock.t - start > timeout:
                s = self.core.status(self.clock.t)
                raise AssertionError("%s not reached within %.1f s of world time; link %s (%s), "
                                     "controller %s" % (what or "condition", timeout, s.link.value,
                                                        s.link_reason, self.program.last_feedback))
            self.tick()
        return self.clock.t - start

    def run_for(self, seconds: float) -> None:
        end = self.clock.t + seconds
        while self.clock.t < end:
            self.tick()

    def freeze(self, seconds: float) -> None:
        """The driver's process stands still for ``seconds`` (SIGSTOP / SIGCONT) while the
        controller runs on."""
        self.frozen = True
        self.run_for(seconds)
        self.frozen = False
        self.next_bus = self.clock.t

    # ------------------------------------------------------------------ shortcuts
    def status(self) -> DriverStatus:
        return self.core.status(self.clock.t)

    def ready(self, timeout: float = 5.0) -> DriverStatus:
        self.run_until(lambda: self.status().motion_possible and self.status().joints_valid
                       and (self.streams or self.core.handshake.ready), timeout, "driver ready")
        return self.status()

    def finish(self, job: MoveJob, timeout: float = 30.0):
        self.run_until(lambda: job.done, timeout, "job %d done" % job.id)
        return job.result

    def executed(self) -> List[Tuple[str, Tuple[int, ...], str]]:
        return [(e.move_type, tuple(e.target), e.outcome.value) for e in self.log.entries()]
