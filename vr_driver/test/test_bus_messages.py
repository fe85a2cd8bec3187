"""The messages between the driver and its bus process (vr_driver.bus.messages): each goes over
the wire and comes back equal; one that is malformed, unknown, or meant for the other side is
refused with an error that says what is wrong. And the one master interface
(pyprofibus_vendor.master_api) that the in-process master and the bus process's stand-in share."""
from __future__ import annotations

import pickle
from multiprocessing import Pipe

import pytest
from pyprofibus_vendor.adapter import AdapterSetup
from pyprofibus_vendor.dp import DiagStatus1, SlaveDiag
from pyprofibus_vendor.dp_master import BusTiming, DpMaster, SlaveHandle, SlaveSpec
from pyprofibus_vendor.errors import DpError, PhyError
from pyprofibus_vendor.master_api import (MasterApi, MasterCounters, MasterSlaveState, SlaveCounters,
                                          SlaveView)
from pyprofibus_vendor.phy import MemoryLink

from vr_driver.bus.health import BusHealthSummary
from vr_driver.bus.messages import (FROM_BUS, TO_BUS, AddSlave, Answer, BusSettings, Channel, Close,
                                    CycleAt, Failed, MessageError, OpenFailed, Opened, Outputs, Report,
                                    SlaveReport, Start, StateChange, Tick, decode)
from vr_driver.bus.process import BusProcessMaster, PipeWake, RemoteSlave, _ReportSender

SPEC = SlaveSpec(8, 0x06C6, bytes.fromhex("1313131123232321"), watchdog=None)
SETTINGS = BusSettings(device="/dev/ttyUSB0", baud=19200, master_address=2, timing=BusTiming.for_baud(19200),
                       cycle_rate_hz=15.0, controller=8, idle_record=bytes(24), watchdog=0.3)
HEALTH = BusHealthSummary(period=0.05, watchdog=0.3, replies=20, max_gap=0.06, jitter_p99=0.004,
                          jitter_max=0.01, worst_gap=0.08, late_gaps=0, scheduling="SCHED_FIFO 20")


def report(health=HEALTH) -> Report:
    counters = MasterCounters(cycles=41, requests=90, reply_wait=0.125)
    slave = SlaveReport(8, MasterSlaveState.DATA_EXCHANGE, 12.5, 3, bytes(range(24)), 12.75,
                        SlaveDiag(DiagStatus1(0), ident=0x06C6), SlaveCounters(requests=44, data_exchanges=40))
    idle = SlaveReport(9, MasterSlaveState.BACKOFF, 1.0, 0, None, None, None, SlaveCounters())
    events = (StateChange(8, MasterSlaveState.CHECK_DIAG, MasterSlaveState.DATA_EXCHANGE, "ready", 12.5, 3),)
    return Report(12.8, 7, 5, counters, (slave, idle), health, 0, events)


TO = [Start(SETTINGS), AddSlave(SPEC), Outputs(8, 3, bytes(24), bytes([1]) * 24, 17), Outputs(9, 0, b"\x01", None, 1),
      Answer(7), CycleAt(12.9), Tick(), Close()]
FROM = [Opened("SCHED_FIFO 20", AdapterSetup("/dev/ttyUSB0", True, 1, 16, ("latency timer 16 -> 1 ms",))),
        Opened("normal scheduling", None), OpenFailed("no such device", 2), OpenFailed("busy", None),
        report(), report(health=None), Failed("serial port /dev/ttyUSB0 failed: gone")]


@pytest.mark.parametrize("message", TO, ids=lambda m: type(m).__name__)
def test_every_message_to_the_bus_comes_back_equal(message):
    assert decode(message.encode(), TO_BUS) == message


@pytest.mark.parametrize("message", FROM, ids=lambda m: type(m).__name__)
def test_every_message_from_the_bus_comes_back_equal(message):
    back = decode(message.encode(), FROM_BUS)
    assert back == message and type(back) is type(message)


def test_a_report_carries_typed_states_and_counters():
    back = decode(report().encode(), FROM_BUS)
    assert back.slaves[0].state is MasterSlaveState.DATA_EXCHANGE
    assert back.slaves[0].counters.data_exchanges == 40 and back.counters.reply_wait == 0.125
    assert back.events[0].new is MasterSlaveState.DATA_EXCHANGE


def test_a_message_for_the_other_side_is_refused():
    with pytest.raises(MessageError, match=r"'r' unknown here \(expected one of"):
        decode(report().encode(), TO_BUS)
    with pytest.raises(MessageError, match="'out' unknown here"):
        decode(Outputs(8, 0, bytes(24), None, 1).encode(), FROM_BUS)


@pytest.mark.parametrize("raw, words", [
    (("out", 8, 0, bytes(24), None), "'out': 4 fields, expected 5"),
    (("out", 8, "0", bytes(24), None, 1), "'out': field 2 is str '0', expected int"),
    (("answer", 1.5), "'answer': field 1 is float 1.5, expected int"),
    (("slave", (8, 0x06C6)), "'slave': field 1 is tuple"),
    (("nonsense",), "'nonsense' unknown here"),
    (["tick"], "is not a tagged tuple"),
    ((), "is not a tagged tuple"),
])
def test_a_malformed_message_to_the_bus_is_refused_naming_what_is_wrong(raw, words):
    with pytest.raises(MessageError, match=words.replace("(", r"\(").replace(")", r"\)")):
        decode(pickle.dumps(raw), TO_BUS)


def test_a_malformed_report_is_refused_naming_what_is_wrong():
    fields = list(pickle.loads(report().encode()))
    bad_state = list(fields)
    bad_state[5] = ((8, "DANCING") + fields[5][0][2:],)
    with pytest.raises(MessageError, match="no slave state 'DANCING'"):
        decode(pickle.dumps(tuple(bad_state)), FROM_BUS)
    bad_counters = list(fields)
    bad_counters[4] = (1, 2, 3)
    with pytest.raises(MessageError, match="MasterCounters .* expected %d numbers" % len(vars(MasterCounters()))):
        decode(pickle.dumps(tuple(bad_counters)), FROM_BUS)
    bad_diag = list(fields)
    bad_diag[5] = (fields[5][0][:6] + (b"\x01",) + fields[5][0][7:],)
    with pytest.raises(MessageError, match="a slave's diagnosis 01: "):
        decode(pickle.dumps(tuple(bad_diag)), FROM_BUS)
    with pytest.raises(MessageError, match="does not load"):
        decode(b"\x80\x05garbage", FROM_BUS)
    assert issubclass(MessageError, PhyError)      # the driver takes it as the bus process failing


def test_a_channel_receives_only_its_sides_messages():
    ours, theirs = Pipe()
    driver, bus = Channel(ours, FROM_BUS), Channel(theirs, TO_BUS)
    driver.send(Answer(3))
    assert bus.poll(1.0) and bus.recv() == Answer(3)
    bus.send(Tick())                      # the bus process never says tick: the driver refuses it
    assert driver.poll(1.0)
    with pytest.raises(MessageError, match="'tick' unknown here"):
        driver.recv()


# ------------------------------------------------------------------------------ one interface
def test_the_in_process_master_and_the_bus_processs_stand_in_share_one_interface():
    assert issubclass(DpMaster, MasterApi) and issubclass(BusProcessMaster, MasterApi)
    assert issubclass(SlaveHandle, SlaveView) and issubclass(RemoteSlave, SlaveView)
    master = DpMaster(MemoryLink.pair()[0], 2, 19200)
    assert not master.paced and master.scheduling == "" and master.health is None and master.adapter is None
    master.poke()                        # nothing to do where the caller's thread runs the cycles
    master.cycle_at(0.0)
    master.answered()
    handle = master.add_slave(SPEC)
    assert handle.carried and handle.stop_outputs is None
    with pytest.raises(DpError, match="3 output bytes, expected 14"):
        handle.outputs = b"abc"
    handle.outputs = bytes(range(14))
    assert handle.outputs == bytes(range(14))


def test_the_bus_process_masters_own_wake_is_a_pipe_set_from_any_thread_and_taken_once():
    """Where the application gives no wake-up, BusProcessMaster's cycle waits on its own
    (PipeWake, which its poke sets): readable once set (twice: still one wake), empty once
    cleared; a set after close raises nothing."""
    import select
    wake = PipeWake()
    fd = wake.fileno()
    assert select.select([fd], [], [], 0.0)[0] == []
    wake.set()
    wake.set()
    assert select.select([fd], [], [], 0.0)[0] == [fd]
    wake.clear()
    assert select.select([fd], [], [], 0.0)[0] == []
    wake.close()
    wake.set()
    wake.clear()


def test_a_report_not_yet_sent_passes_its_state_changes_and_health_on_to_the_next():
    """The bus process's report sender: a driver that does not read gets the newest report, with the
    state changes and the health summary of the one it replaced."""
    ours, theirs = Pipe()
    sender = _ReportSender(Channel(theirs, TO_BUS))
    up = StateChange(8, MasterSlaveState.CHECK_DIAG, MasterSlaveState.DATA_EXCHANGE, "ready", 1.0, 1)
    down = StateChange(8, MasterSlaveState.DATA_EXCHANGE, MasterSlaveState.BACKOFF, "no reply", 1.1, 1)
    with sender._cond:                   # the sender's thread cannot take the first before the second
        sender.post(Report(1.0, 1, 0, MasterCounters(), (), HEALTH, 0, (up,)))
        sender.post(Report(1.1, 2, 0, MasterCounters(cycles=2), (), None, 0, (down,)))
    assert ours.poll(5.0)
    got = decode(ours.recv_bytes(), FROM_BUS)
    assert got.seq == 2 and got.counters.cycles == 2
    assert got.events == (up, down) and got.health == HEALTH
    sender.final(Failed("the end"))
    assert isinstance(decode(ours.recv_bytes(), FROM_BUS), Failed)
