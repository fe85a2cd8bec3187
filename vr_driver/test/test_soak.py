"""The short soak (issue 10; issue 16 for protocol v2; v3): bench/soak.py's run with ~100 targets, 2 %
byte corruption both ways (v2: 40 streamed moves, v3: 60, both 0.5 %) and two line cuts, DriverCore against the virtual G2 controller over a real pty pair, no ROS.

Nothing may be done twice and nothing lost without a reason; every cut must be ridden out or
reconnected within 1.5 s of the restore; the core's status must never pause for more than 1.1 s;
the arm never leaves the workspace box, and the driver's joints at rest are the arm's.
The full run (thousands of targets) is `scripts/bench soak -- --targets 5000 --cut-every 20`."""
from __future__ import annotations

import importlib.util
import os
import sys

import pytest

from _priority import threads_at_real_time

_BENCH = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))),
                      "bench", "soak.py")


def _load_soak():
    spec = importlib.util.spec_from_file_location("vr_bench_soak", _BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module           # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


soak = _load_soak()


#: protocol -> (moves, byte corruption, shortest share of the targets executed). v2's records are
#: 72 bytes (81 on the wire): 0.5 % per byte fails about as many telegrams as v1's 2 % on its 23; a
#: v2 move streams many targets, and a cut ends the rest of its stream (aborted, with the reason).
#: v3 streams Cartesian targets (24 bytes out, 28 in: v2's exactly-once rules, with a check word and
#: the seq copy instead of the CRC) at v2's 0.5 %; its shorter records make it faster: 60 moves keep
#: the run past the second cut with > 500 bytes corrupted (about 30 s)
RUNS = {"v1": (100, 0.02, 0.8), "v2": (40, 0.005, 0.6), "v3": (60, 0.005, 0.6)}
#: SCHED_FIFO priority of the run's threads (the driver core's bus, the virtual G2's) where the system
#: allows it, as the driver's bus process runs (doc/reliability.md): scripts/test then runs the soak
#: beside the computing tests, which cannot delay it; below the commissioning test's (10 and 20)
SOAK_PRIORITY = 5


@pytest.fixture(scope="module", params=sorted(RUNS))
def result(request, kin, tmp_path_factory):
    targets, corrupt, _share = RUNS[request.param]
    config = soak.SoakConfig(
        targets=targets, corrupt=corrupt, cut_times=(8.0, 20.0), cut_min=0.5, cut_max=1.0, seed=7,
        speed_factor=100.0, cycle_rate=100.0, driver_params={"accept_timeout": 0.5},
        workdir=str(tmp_path_factory.mktemp("soak")), protocol=request.param)
    with threads_at_real_time(SOAK_PRIORITY):
        res = soak.run_soak(config, kin=kin)
    print("\n".join(res.summary() + [res.final_line()]))
    return res


def test_the_run_completed_with_faults_injected(result):
    assert result.complete, result.error
    assert result.jobs == result.config.targets and result.commanded >= result.config.targets
    assert len(result.cuts) == 2, "the run ended before the second cut"
    assert result.link_counters["corrupted"] > 500 and result.link_counters["cut_discarded"] > 0
    assert result.executed + result.rejected + result.aborted + result.lost == result.commanded


def test_nothing_done_twice(result):
    assert result.duplicated == 0, result.duplicate_details
    assert result.unknown_entries == 0, result.unknown_details      # no corrupted target executed


def test_nothing_lost_without_a_reason(result):
    assert result.lost == 0 and result.hung == 0, result.lost_details
    assert result.executed >= RUNS[result.config.protocol][2] * result.commanded, result.summary()


def test_every_cut_reconnects_within_1_5_s(result):
    assert result.unrecovered_cuts == 0
    assert all(t <= 1.5 for t in result.reconnect_times), result.reconnect_times


def test_the_arm_never_left_the_box_and_the_driver_knew_its_joints(result):
    """Every bus cycle the arm's exact TCP against the workspace box, and at rest the driver's
    joints against the arm's (v1 reports only a rounded pose: the configuration is tracked)."""
    assert result.outside_samples == 0, (result.outside_max, result.outside_pose)
    assert result.mismatch_samples == 0, result.mismatch_max


def test_status_never_pauses_longer_than_1_1_s(result):
    assert result.status_calls >= 5 * result.duration       # published all along
    assert result.status_gap_max <= 1.1, (result.status_gap_max, result.status_gap_at)


def test_final_line_format(result):
    line = result.final_line()
    assert [kv.split("=")[0] for kv in line.split()] == [
        "commanded", "executed", "rejected", "aborted", "duplicated", "lost", "reconnect_max_s",
        "status_gap_max_s"]


# ------------------------------------------------------ the two-telegram rule, deterministically
# What the soak found: at 2 % byte corruption without parity about 1.7e-4 of the Data_Exchange
# requests pass the FCS with wrong contents; the controller acted on one. The virtual controller
# now acts on a record only once it arrived unchanged in two consecutive telegrams.

from pyprofibus_vendor.dp import PrmStationStatus, Sap, SetPrm, request_frame  # noqa: E402
from pyprofibus_vendor.dp_slave import SlaveState  # noqa: E402
from pyprofibus_vendor.fdl import FcbRequester  # noqa: E402
from vr_driver.controller.program_v1 import ControllerProgramV1 as ControllerProgram  # noqa: E402
from vr_driver.controller.virtual_controller import robot_slave
from vr_driver.protocol.v1 import Command, ControllerState, WireMoveType  # noqa: E402
from vr_driver.controller.arm import Outcome, SimArm  # noqa: E402


class Program:
    """A robot DpSlave + SimArm + ControllerProgram on a fake clock, fed telegram by telegram."""

    def __init__(self, kin, confirm: bool) -> None:
        self.t = 100.0
        self.slave = robot_slave(4, lambda: self.t)
        self.arm = SimArm(kin, speed_factor=50.0, clock=lambda: self.t)
        self.prog = ControllerProgram(self.slave, self.arm, confirm_records=confirm)
        self.fcb = FcbRequester()
        prm = SetPrm(ident=0x06C6, station_status=PrmStationStatus.LOCK_REQ | PrmStationStatus.WD_ON,
                     wd_fact1=10, wd_fact2=1)
        self._call(Sap.SET_PRM, prm.encode())
        self._call(Sap.CHK_CFG, self.slave.cfg)
        assert self.slave.state is SlaveState.DATA_EXCH

    def _call(self, sap, payload):
        fcb, fcv = self.fcb.bits()
        reply = self.slave.handle(request_frame(4, 2, fcb, fcv, sap, payload), self.t)
        self.fcb.acknowledge()
        return reply

    def telegram(self, command: Command, loops: int = 1) -> ControllerState:
        """One Data_Exchange carrying ``command``, then ``loops`` program loops of 10 ms."""
        self._call(None, command.encode())
        state = None
        for _ in range(loops):
            self.t += 0.01
            state = self.prog.step(self.t).state
        return state

    def until_done(self, command: Command) -> None:
        for _ in range(200):
            if self.telegram(command, loops=5) is ControllerState.DONE:
                return
        raise AssertionError("no DONE for %s" % command.describe())


TARGET_A = Command.from_pose((1000, 200, 800, 0, 45, 0), WireMoveType.PTP)
CORRUPTED = Command.from_pose((1000, 200, 1006, 0, 95, 0), WireMoveType.PTP)   # bytes changed


def test_a_single_corrupted_telegram_never_starts_a_target(kin):
    p = Program(kin, confirm=True)
    idle = TARGET_A.with_request(False)
    for _ in range(3):
        assert p.telegram(idle) is ControllerState.READY
    assert p.telegram(CORRUPTED) is ControllerState.READY          # seen once: not acted on
    assert p.telegram(TARGET_A) is ControllerState.READY          # the true record, first time
    assert p.telegram(TARGET_A) is ControllerState.BUSY           # confirmed
    assert [tuple(e.target) for e in p.prog.log.entries()] == []  # nothing finished yet
    p.until_done(TARGET_A)
    assert [(tuple(e.target), e.outcome) for e in p.prog.log.entries()] == \
        [(TARGET_A.values, Outcome.EXECUTED)]


@pytest.mark.parametrize("confirm, executions", [(True, 1), (False, 2)])
def test_a_corrupted_flag_0_while_done_cannot_restart_the_target(kin, confirm, executions):
    """DONE, the master has not seen it yet (its flag still 1); one telegram arrives with the
    flag corrupted to 0, then the flag-1 telegrams go on: without the rule the controller
    releases, sees the flag 1 again and runs the same target a second time."""
    p = Program(kin, confirm=confirm)
    idle = TARGET_A.with_request(False)
    for _ in range(3):
        p.telegram(idle)
    p.telegram(TARGET_A)
    p.until_done(TARGET_A)
    p.telegram(idle)                                   # the corrupted one
    for _ in range(20):
        p.telegram(TARGET_A, loops=5)                  # the master still waits for DONE
    done = [e for e in p.prog.log.entries() if e.outcome is Outcome.EXECUTED]
    assert len(done) == executions


def test_a_flag_0_record_arms_the_program_even_between_two_loops(kin):
    """A new session: the master's idle record arrives twice, then its request twice, all before
    the program loop runs: the request is new (the flag was seen at 0), not a stale one."""
    p = Program(kin, confirm=True)
    for command in (TARGET_A.with_request(False),) * 2 + (TARGET_A,) * 2:
        p.telegram(command, loops=0)
    assert p.telegram(TARGET_A) is ControllerState.BUSY
    p.until_done(TARGET_A)
    assert [e.outcome for e in p.prog.log.entries()] == [Outcome.EXECUTED]


def test_a_session_that_starts_with_the_flag_raised_is_still_refused(kin):
    p = Program(kin, confirm=True)
    for _ in range(3):
        p.telegram(TARGET_A, loops=0)
    assert p.telegram(TARGET_A) is ControllerState.REJECTED
    assert "already raised" in p.prog.log.entries()[0].reason
