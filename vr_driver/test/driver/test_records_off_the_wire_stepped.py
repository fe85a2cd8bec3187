"""Records the bus never carried, stepped with a fake clock in one thread.

With the bus in a process of its own (vr_driver.bus.process) the driver's records reach the wire
at the bus process's next cycle -- if they arrive before it begins. A record made between two cycles
(a job posted: the driver steps at once) or made late (the node's interpreter busy) waits for the
cycle after; and a newer record made before that cycle replaces it: it never was on the wire. The bus
process reports which record each cycle carried (``RemoteSlave.outputs_on_wire``); the stream
sequencer, which sends the next target before the controller acknowledged the last, must not move on
past a record that has not gone out. Found on the wrist bench (v3, 19.2 kbit/s paced line): START of a
stream's first target made between two cycles, replaced by the second target sent ahead; the first
went out a record later, the controller ignored the second (one number ahead of what it had taken),
the master fell back to the first until the acknowledgement came, and the arm stopped at the first
point waiting for the second.

:class:`LateRecords` plays the bus process's side on the stepped world's in-process master: the
records it is told are late miss the next cycle (that cycle carries the image before them).
"""
from __future__ import annotations

import math
from typing import Callable

import pytest

from vr_driver.driver.supervision import SUCCEEDED
from vr_driver.driver.trajectories import SUCCESSFUL

from _paced import PacedWorld
from test_wire_supervision_stepped import START, supervise, sweep, validated

DEG = math.pi / 180.0
THERE = START[:4] + (-24 * DEG,) + START[5:]


class LateRecords:
    """The controller's slave handle of the in-process master, as the bus process shows it to the
    driver: a record set is carried by the next DP cycle, unless ``late(n)`` (n: the record's
    serial, 1, 2, ...) -- then by the one after, if no newer record replaced it meanwhile.
    ``outputs_on_wire`` as :class:`~vr_driver.bus.process.RemoteSlave`'s."""

    def __init__(self, handle, master, late: Callable[[int], bool], report: bool = True) -> None:
        object.__setattr__(self, "_handle", handle)
        object.__setattr__(self, "_report", report)
        object.__setattr__(self, "_late", late)
        object.__setattr__(self, "_serial", 0)
        object.__setattr__(self, "_pending", None)      # [serial, data, cycles to wait]
        object.__setattr__(self, "carried", 0)
        object.__setattr__(self, "lost", 0)             # records replaced before any cycle carried them
        cycle = master.cycle

        def cycle_carrying(*args, **kwargs):
            pending = self._pending
            if pending is not None:
                if pending[2] > 0:
                    pending[2] -= 1                      # this cycle carries the image before it
                else:
                    self._handle.outputs = pending[1]
                    object.__setattr__(self, "carried", pending[0])
                    object.__setattr__(self, "_pending", None)
            return cycle(*args, **kwargs)
        master.cycle = cycle_carrying

    def __getattr__(self, name):
        return getattr(self._handle, name)

    def __setattr__(self, name, value):
        if name != "outputs":
            setattr(self._handle, name, value)
            return
        data = bytes(value)
        current = self._pending[1] if self._pending is not None else self._handle.outputs
        if data == current:
            return                                      # the same message: not sent again
        if self._pending is not None:
            object.__setattr__(self, "lost", self.lost + 1)
        serial = self._serial + 1
        object.__setattr__(self, "_serial", serial)
        object.__setattr__(self, "_pending", [serial, data, 1 if self._late(serial) else 0])

    @property
    def outputs(self) -> bytes:
        return self._pending[1] if self._pending is not None else self._handle.outputs

    @property
    def outputs_on_wire(self) -> bool:
        """(``report`` False: always True -- a driver told nothing, as before the bus process said it)"""
        return self.carried >= self._serial or not self._report


def late_world(kin, protocol, late, respect=True):
    """A paced world whose controller records are late as ``late`` says; ``respect`` False: the
    driver is not told (every record reads as on the wire, as before the bus process reported it)."""
    world = PacedWorld(kin, protocol=protocol, initial_pose=kin.fk_pose(START))
    world.ready()
    link = world.core.link
    proxy = LateRecords(link._slave, link._master, late, report=respect)
    link._slave = proxy
    return world, proxy


def run_sweep(world):
    traj = validated(world, *sweep(world.status().joints, THERE, n=20, duration=2.0))
    sup, out = supervise(world, traj)
    return traj, sup.run.jobs[0], out


def wire_seqs(world):
    return [e.seq for e in world.log.entries()]


#: which records miss the next cycle (every other: each target sent ahead would replace the one
#: before it, which had not gone out yet)
PATTERNS = {
    "every third record late": lambda n: n % 3 == 0,
    "every other record late": lambda n: n % 2 == 0,
}


@pytest.mark.parametrize("pattern", sorted(PATTERNS))
def test_a_stream_sends_ahead_only_past_records_the_bus_carried(kin, pattern):
    """v3 (one slot a record, the next target sent before the acknowledgement) on the 19.2 kbit/s
    line, 0.1 s segments, with records late as the pattern says: the look-ahead never runs dry,
    every target on the wire once, in order, on time. (v2 sends nothing ahead: its two slots always
    start at the first target not acknowledged.)"""
    world, proxy = late_world(kin, "v3", PATTERNS[pattern])
    traj, job, out = run_sweep(world)
    assert (out.state, out.error_code) == (SUCCEEDED, SUCCESSFUL), out.error_string
    assert job.gaps == 0, "the arm stopped %d times waiting for a target (%d records replaced before they " \
                          "went out)" % (job.gaps, proxy.lost)
    seqs = wire_seqs(world)
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs) == len(job.points)
    assert out.elapsed <= 1.10 * traj.duration + 0.3, (out.elapsed, traj.duration)


def test_the_same_records_without_the_report_lose_targets(kin):
    """The check above can fail: told nothing (every record taken as sent), the sequencer sends the
    next target ahead in place of one that never went out, and the arm waits for it."""
    world, proxy = late_world(kin, "v3", PATTERNS["every other record late"], respect=False)
    _traj, job, _out = run_sweep(world)
    assert proxy.lost > 0
    assert job.gaps > 0
