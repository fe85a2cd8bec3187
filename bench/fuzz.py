#!/usr/bin/python3
"""Fuzz the PROFIBUS engines with random and mutated telegrams; print what each did with them.

Three targets, each fed ``--frames`` telegrams (default 10^6 each):
  deframer  mutated telegram streams cut into random chunks -> Deframer.feed
  slave     mutated master requests -> decode_frame -> DpSlave.handle (the virtual controller's engine)
  master    mutated slave replies -> the DpMaster state machine, through a link that answers every
            request with a mutated version of the right reply (injected clock, no sleeping)

The corpus is what our master and slave really exchange (start-up, Data_Exchange, diag, Global_Control,
Get_Cfg), recorded in process. Mutations: bit flips, byte changes, drops, inserts, truncation,
duplication, splices of two telegrams, and pure random blobs.

Pass criteria (printed; exit 1 on a violation): no exception other than the stack's own typed errors
escapes; every telegram the deframer returns is really in its input; the slave delivers outputs and the
master delivers inputs only from telegrams whose FCS is intact and that decode as Data_Exchange.

    scripts/bench fuzz                      # 10^6 per target
    scripts/bench fuzz -- --frames 20000    # quicker
"""
from __future__ import annotations

import argparse
import collections
import logging
import os
import random
import sys
import time
from typing import Callable, Dict, List, Optional

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(REPO, "pyprofibus_vendor", "src"))

from pyprofibus_vendor.dp_master import DpMaster, SlaveSpec  # noqa: E402
from pyprofibus_vendor.dp_slave import DpSlave  # noqa: E402
from pyprofibus_vendor.errors import ProfibusError  # noqa: E402
from pyprofibus_vendor.fdl import Deframer, Frame, RespondingLink, decode_frame  # noqa: E402

IDENT = 0x06C6
CFG = bytes.fromhex("13 13 13 11 23 23 23 21")
MASTER, SLAVE = 2, 4


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


class Recorder(RespondingLink):
    """Our slave on the far end of an in-process link; records every request and reply."""

    def __init__(self, slave: DpSlave, clock: Clock) -> None:
        super().__init__("recorder")
        self.slave, self.clock = slave, clock
        self.pairs: List[tuple] = []

    def respond(self, frame: Frame) -> Optional[bytes]:
        reply = self.slave.handle(frame, self.clock())
        raw = reply.encode() if reply is not None else None
        self.pairs.append((frame.encode(), raw))
        return raw


def record_corpus(cycles: int = 60) -> List[tuple]:
    """(request bytes, reply bytes or None) of a real start-up plus Data_Exchange cycles."""
    clock = Clock()
    slave = DpSlave(SLAVE, IDENT, CFG, clock=clock)
    slave.on_outputs = lambda data: setattr(slave, "inputs", bytes(b ^ 0x5A for b in data))
    link = Recorder(slave, clock)
    master = DpMaster(link, MASTER, 187500, clock=clock)
    handle = master.add_slave(SlaveSpec(SLAVE, IDENT, CFG, watchdog=1.0))
    rng = random.Random(1)
    for _ in range(cycles):
        handle.outputs = bytes(rng.randrange(256) for _ in range(14))
        master.step(clock.t)
        clock.t += 0.002
    master.get_cfg(SLAVE)
    master.read_inputs(SLAVE)
    from pyprofibus_vendor.dp import GcCommand
    master.global_control(GcCommand.CLEAR_DATA)
    for _ in range(5):
        master.step(clock.t)
        clock.t += 0.002
    return link.pairs


def mutate(rng: random.Random, raw: bytes, other: bytes) -> bytes:
    b = bytearray(raw)
    op = rng.randrange(9)
    if op == 0 and b:                                   # flip one bit
        i = rng.randrange(len(b))
        b[i] ^= 1 << rng.randrange(8)
    elif op == 1 and b:                                 # change bytes
        for _ in range(rng.randint(1, 3)):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif op == 2 and len(b) > 1:                        # drop
        del b[rng.randrange(len(b))]
    elif op == 3:                                       # insert
        b.insert(rng.randrange(len(b) + 1), rng.randrange(256))
    elif op == 4 and b:                                 # truncate
        del b[rng.randrange(len(b)):]
    elif op == 5:                                       # duplicate
        b = b + b
    elif op == 6:                                       # splice with another telegram
        cut = rng.randrange(len(b) + 1)
        b = b[:cut] + bytearray(other[rng.randrange(len(other) + 1):])
    elif op == 7:                                       # random blob
        b = bytearray(rng.randrange(256) for _ in range(rng.randrange(1, 60)))
    # op 8: unchanged (valid telegrams must keep working among the garbage)
    return bytes(b)


def fuzz_deframer(corpus: List[bytes], n: int, rng: random.Random) -> Dict[str, int]:
    stats: Dict[str, int] = collections.Counter()
    d = Deframer()
    done = 0
    history = b""                                       # the input's tail: a telegram may start in
    while done < n:                                     # an earlier batch (the deframer keeps it)
        batch = [mutate(rng, rng.choice(corpus), rng.choice(corpus)) for _ in range(rng.randint(1, 20))]
        stream = b"".join(batch)
        history = (history + stream)[-4096:]
        done += len(batch)
        pos = 0
        try:
            while pos < len(stream):
                step = rng.randint(1, 64)
                for frame in d.feed(stream[pos:pos + step]):
                    stats["frames out"] += 1
                    if frame.encode() not in history:
                        stats["VIOLATION frame not in input"] += 1
                pos += step
        except ProfibusError as exc:
            stats["typed error %s" % type(exc).__name__] += 1
            d.reset()
        except Exception as exc:  # the finding this bench exists for
            stats["VIOLATION %s: %s" % (type(exc).__name__, exc)] += 1
            d.reset()
    c = d.counters
    stats.update({"telegrams in": done, "garbage bytes": c.garbage_bytes, "fcs errors": c.fcs_errors,
                  "format errors": c.format_errors})
    return stats


def fuzz_slave(requests: List[bytes], n: int, rng: random.Random) -> Dict[str, int]:
    stats: Dict[str, int] = collections.Counter()
    clock = Clock()
    delivered: List[bytes] = []
    slave = DpSlave(SLAVE, IDENT, CFG, clock=clock)
    slave.on_outputs = delivered.append
    valid_outputs = set()
    for raw in requests:
        try:
            f = decode_frame(raw)
            if getattr(f, "dsap", 1) is None and len(getattr(f, "data", b"")) == 14:
                valid_outputs.add(bytes(f.data))
        except ProfibusError:
            pass
    # the DX part of the recorded sequence loops; half of the telegrams follow it unchanged, so the
    # slave keeps reaching Data_Exchange and the garbage hits it in every state
    # a Data_Exchange request: SD2, LE = DA SA FC + 14 data bytes, no SAP extension (DA bit 7 clear)
    first_dx = next((i for i, raw in enumerate(requests)
                     if raw[0] == 0x68 and raw[1] == 3 + 14 and not raw[4] & 0x80), len(requests) - 1)
    index = 0
    for i in range(n):
        if rng.random() < 0.5:
            raw = requests[index]
            index = index + 1 if index + 1 < len(requests) else first_dx
            if slave.state.name != "DATA_EXCH" and index > first_dx:
                index = 0                               # knocked out: the master starts it up again
        else:
            raw = mutate(rng, rng.choice(requests), rng.choice(requests))
        clock.t += rng.choice((0.0005, 0.002, 0.01, 0.5))      # sometimes long enough for the watchdog
        try:
            frame = decode_frame(raw)
        except ProfibusError as exc:
            stats["rejected by decode: %s" % type(exc).__name__] += 1
            continue
        except Exception as exc:
            stats["VIOLATION decode %s: %s" % (type(exc).__name__, exc)] += 1
            continue
        before = len(delivered)
        try:
            reply = slave.handle(frame, clock.t)
            stats["replied" if reply is not None else "no reply"] += 1
        except ProfibusError as exc:
            stats["typed error %s" % type(exc).__name__] += 1
        except Exception as exc:
            stats["VIOLATION handle %s: %s" % (type(exc).__name__, exc)] += 1
        for out in delivered[before:]:
            # outputs come only from an intact Data_Exchange (its data exactly), or are the safe
            # all-zero image after a watchdog expiry / leaving Data_Exchange
            if len(out) != 14 or (bytes(getattr(frame, "data", b"")) != out and out != bytes(14)):
                stats["VIOLATION outputs not from the telegram"] += 1
            stats["outputs delivered"] += 1
        if slave.state.name == "DATA_EXCH":
            stats["loops in DATA_EXCH"] += 1
    stats["telegrams in"] = n
    return stats


class FuzzLink(RespondingLink):
    """Answers each master request with a mutated version of the recorded reply to it."""

    def __init__(self, replies: Dict[bytes, bytes], corpus: List[bytes], rng: random.Random) -> None:
        super().__init__("fuzz link")
        self.replies, self.corpus, self.rng = replies, corpus, rng
        self.sent_replies: List[bytes] = []

    def respond(self, frame: Frame) -> Optional[bytes]:
        raw = frame.encode()
        good = self.replies.get(raw) or self.replies.get(self._key(raw))
        if good is None:
            good = self.rng.choice(self.corpus)
        bad = mutate(self.rng, good, self.rng.choice(self.corpus))
        self.sent_replies.append(bad)
        return bad

    @staticmethod
    def _key(raw: bytes) -> bytes:
        return raw[:7]


def fuzz_master(pairs: List[tuple], n: int, rng: random.Random) -> Dict[str, int]:
    stats: Dict[str, int] = collections.Counter()
    replies: Dict[bytes, bytes] = {}
    for req, rep in pairs:
        if rep is not None:
            replies.setdefault(req, rep)
            replies.setdefault(req[:7], rep)
    corpus = [rep for _req, rep in pairs if rep is not None]
    clock = Clock()
    link = FuzzLink(replies, corpus, rng)
    master = DpMaster(link, MASTER, 187500, clock=clock, backoff_min=0.001, backoff_max=0.002,
                      state_limit=0.05)
    handle = master.add_slave(SlaveSpec(SLAVE, IDENT, CFG, watchdog=1.0))
    last_inputs = None
    while len(link.sent_replies) < n:
        try:
            wake = master.step(clock.t)
        except ProfibusError as exc:
            stats["typed error %s" % type(exc).__name__] += 1
            wake = clock.t + 0.001
        except Exception as exc:
            stats["VIOLATION %s: %s" % (type(exc).__name__, exc)] += 1
            break
        clock.t = max(clock.t + 0.0001, min(wake, clock.t + 0.01))
        if handle.inputs is not None and handle.inputs != last_inputs:
            last_inputs = handle.inputs
            stats["inputs delivered"] += 1
            # inputs come only from an intact DX reply: its bytes are in what the link sent
            tail = link.sent_replies[-1] if link.sent_replies else b""
            if bytes(last_inputs) not in tail:
                stats["VIOLATION inputs not from the last reply"] += 1
    c = master.counters
    stats.update({"telegrams in": len(link.sent_replies), "requests": c.requests, "retries": c.retries,
                  "timeouts": c.timeouts, "invalid replies": c.invalid_replies,
                  "fcs errors": c.fcs_errors, "losses": c.losses, "reconnects": c.reconnects,
                  "data exchanges": handle.counters.data_exchanges})
    return stats


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=1_000_000, help="telegrams per target (default 10^6)")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--targets", default="deframer,slave,master")
    args = parser.parse_args(argv)
    logging.disable(logging.CRITICAL)     # millions of state changes would be logged otherwise
    rng = random.Random(args.seed)
    pairs = record_corpus()
    requests = [req for req, _ in pairs]
    corpus = requests + [rep for _, rep in pairs if rep is not None]
    print("=== bench/fuzz.py: %d telegrams per target, seed %d, corpus %d recorded telegrams"
          % (args.frames, args.seed, len(corpus)))
    runs: Dict[str, Callable[[], Dict[str, int]]] = {
        "deframer": lambda: fuzz_deframer(corpus, args.frames, rng),
        "slave": lambda: fuzz_slave(requests, args.frames, rng),
        "master": lambda: fuzz_master(pairs, args.frames, rng),
    }
    violations = 0
    for name in [t.strip() for t in args.targets.split(",") if t.strip()]:
        t0 = time.perf_counter()
        stats = runs[name]()
        dt = time.perf_counter() - t0
        bad = sum(v for k, v in stats.items() if k.startswith("VIOLATION"))
        violations += bad
        print("--- %s: %d telegrams in %.1f s (%.1f us each), violations %d"
              % (name, stats["telegrams in"], dt, 1e6 * dt / max(1, stats["telegrams in"]), bad))
        for key in sorted(stats):
            if key != "telegrams in":
                print("  %-44s %d" % (key, stats[key]))
    print("RESULT: %s (violations %d)" % ("PASS" if violations == 0 else "FAIL", violations))
    return 0 if violations == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
