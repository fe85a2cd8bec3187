#!/usr/bin/python3
"""The bus process's report, every cycle: CPU and bytes per report (printed, never asserted).

    scripts/bench bus_messages [-- --reports 20000 --repeats 3 --rate 15 | --quick]

One report of a controller in Data_Exchange (24-byte inputs, its last Slave_Diag) and an I/O
station, as vr_driver.bus.process makes it: built from the DP master's slaves, encoded, decoded
and taken as the driver takes it (vr_driver.bus.messages), time.process_time per report. The
health summary travels once a second (at --rate reports a second), as the bus process sends it.

For scale, the same content in the layout the bus process used before issue 47 (a dict of
positional tuples, counters as dicts, the diagnosis and the health summary pickled every report):
built, pickled, loaded and applied by attribute, as it was. Alternated within each repeat; medians.
"""
from __future__ import annotations

import argparse
import pickle
import statistics
import time

from pyprofibus_vendor.dp import SlaveDiag
from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec
from pyprofibus_vendor.master_api import MasterCounters, MasterSlaveState, SlaveCounters
from pyprofibus_vendor.phy import MemoryLink

from vr_driver.bus.health import BusHealth
from vr_driver.bus.messages import FROM_BUS, Report, SlaveReport, decode

SPECS = (SlaveSpec(8, 0x06C6, bytes.fromhex("1313131123232321"), watchdog=None),
         SlaveSpec(9, 0x1234, bytes.fromhex("1010"), watchdog=None))


class Side:
    """The bus process's master and what the driver keeps of it."""

    def __init__(self) -> None:
        self.master = DpMaster(MemoryLink.pair()[0], 2, 19200)
        for spec in SPECS:
            handle = self.master.add_slave(spec)
            handle._store_inputs(bytes(spec.input_size or 0), 1.0)
            handle.last_diag = SlaveDiag(ident=spec.ident)
        health = BusHealth(0.05, 0.3)
        for i in range(100):
            health.reply(0.05 * i)
        self.summary = health.summary(5.0)
        self.slaves = {spec.address: [None, SlaveCounters()] for spec in SPECS}
        self.counters = MasterCounters()
        self.health = None

    def typed(self, seq: int, with_health: bool) -> int:
        slaves = tuple(SlaveReport(s.address, s.state, s.state_since, 1, s.inputs, s.inputs_time, s.last_diag,
                                   SlaveCounters(*vars(s.counters).values())) for s in self.master.slaves)
        data = Report(float(seq), seq, seq, MasterCounters(*vars(self.master.counters).values()), slaves,
                      self.summary if with_health else None, 0, ()).encode()
        report = decode(data, FROM_BUS)
        for s in report.slaves:
            kept = self.slaves[s.address]
            kept[0], kept[1] = (s.state, s.since, s.session, s.inputs, s.inputs_time, s.diag), s.counters
        self.counters = report.counters
        if report.health is not None:
            self.health = report.health
        return len(data)

    def tuples(self, seq: int, with_health: bool) -> int:
        slaves = [(s.address, s.state.value, s.state_since, 1, s.inputs, s.inputs_time, s.last_diag,
                   dict(vars(s.counters))) for s in self.master.slaves]
        data = pickle.dumps(("r", {"time": float(seq), "seq": seq, "carried": seq,
                                   "counters": dict(vars(self.master.counters)), "slaves": slaves,
                                   "health": self.summary, "dropped_events": 0}, []))
        report = pickle.loads(data)[1]
        for address, state, since, session, inputs, inputs_time, diag, counters in report["slaves"]:
            kept = self.slaves[address]
            kept[0] = (MasterSlaveState(state), since, session, inputs, inputs_time, diag)
            for key, value in counters.items():
                setattr(kept[1], key, value)
        for key, value in report["counters"].items():
            setattr(self.counters, key, value)
        self.health = report["health"]
        return len(data)


def per_report(make, n: int, rate: int) -> tuple:
    start = time.process_time()
    size = 0
    for i in range(n):
        size += make(i, i % rate == 0)
    return (time.process_time() - start) / n, size / n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reports", type=int, default=20000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rate", type=int, default=15, help="reports a second (the health summary once a second)")
    ap.add_argument("--quick", action="store_true", help="2000 reports, 1 repeat")
    args = ap.parse_args()
    if args.quick:
        args.reports, args.repeats = 2000, 1
    side = Side()
    typed, tuples = [], []
    for _ in range(args.repeats):
        typed.append(per_report(side.typed, args.reports, args.rate))
        tuples.append(per_report(side.tuples, args.reports, args.rate))
    t_cpu, t_bytes = statistics.median(c for c, _ in typed), statistics.median(b for _, b in typed)
    o_cpu, o_bytes = statistics.median(c for c, _ in tuples), statistics.median(b for _, b in tuples)
    print("typed messages: %.1f us CPU and %.0f bytes a report (encode, decode, take)" % (1e6 * t_cpu, t_bytes))
    print("tagged tuples (before issue 47): %.1f us CPU and %.0f bytes a report" % (1e6 * o_cpu, o_bytes))
    print("typed / tuples: CPU %.2f, bytes %.2f" % (t_cpu / o_cpu, t_bytes / o_bytes))


if __name__ == "__main__":
    main()
