"""Shared by the controller tests (test_controller_sim.py, test_controller_v2.py,
test_controller_v3.py): a fake clock and a minimal DP master whose telegrams go straight into the
virtual controller's DpSlave (``DpSlave.handle``), one Data_Exchange per program loop.

- :class:`SlaveRig`: the clock, one telegram (:meth:`~SlaveRig.call`), parameterising the slave
  into Data_Exchange with its own Chk_Cfg (:meth:`~SlaveRig.connect`); the subclass builds
  ``self.slave``, the program and the arm, and its ``loop``.
- :class:`StreamRig`: the loop of a streaming protocol (v2, v3): ``self.record`` every bus cycle,
  or, with ``self.stream`` set, what :meth:`~StreamRig.streamed_record` makes of it; the subclass
  says how its records are encoded and decoded."""
from __future__ import annotations

from typing import Any, Callable, List, Optional, Sequence, Tuple

from pyprofibus_vendor.dp import PrmStationStatus, Sap, SetPrm, request_frame
from pyprofibus_vendor.dp_slave import SlaveState
from pyprofibus_vendor.fdl import FcbRequester

from vr_driver.errors import ProtocolError
from vr_driver.protocol.v2 import StreamState

MASTER = 2


class SlaveRig:
    def __init__(self, period: float, watchdog_units: int = 10) -> None:
        self.t = 1000.0
        self.period = period
        self.fcb = FcbRequester()
        self.watchdog_units = watchdog_units      # x 10 ms
        self.exchanging = True
        self.last_rx: Optional[float] = None
        self.slave: Any = None                    # the subclass's DpSlave

    def clock(self) -> float:
        return self.t

    def call(self, sap, payload=b""):
        fcb, fcv = self.fcb.bits()
        reply = self.slave.handle(request_frame(4, MASTER, fcb, fcv, sap, payload), self.t)
        self.fcb.acknowledge()
        self.last_rx = self.t
        return reply

    def connect(self) -> None:
        prm = SetPrm(ident=0x06C6, station_status=PrmStationStatus.LOCK_REQ | PrmStationStatus.WD_ON,
                     wd_fact1=self.watchdog_units, wd_fact2=1)
        self.call(Sap.SET_PRM, prm.encode())
        self.call(Sap.CHK_CFG, self.slave.cfg)
        assert self.slave.state is SlaveState.DATA_EXCH
        self.fcb = FcbRequester()
        self.loop()

    def loop(self, n: int = 1) -> Any:
        raise NotImplementedError


class StreamRig(SlaveRig):
    """Needs ``self.prog``, ``self.arm``, ``self.record`` (the idle command) from the subclass."""

    def __init__(self, period: float, watchdog_units: int = 10) -> None:
        super().__init__(period, watchdog_units)
        self.stream: List[Any] = []
        self.master_fb: Optional[Any] = None
        self.trace: List[Tuple[float, Any, Tuple[float, ...]]] = []

    # --------------------------------------------------------------- the protocol's part
    def encode(self, record: Any) -> bytes:
        raise NotImplementedError

    def decode(self, data: bytes) -> Any:
        raise NotImplementedError

    def streamed_record(self) -> Any:
        raise NotImplementedError

    def observe(self) -> None:
        """After every program loop (a subclass records what it needs)."""

    def accepted_index(self) -> int:
        """The index in ``self.stream`` of the first target the controller has not taken (by the
        accepted_seq of the feedback the master last received)."""
        seqs = [s.seq for s in self.stream]
        accepted = self.master_fb.accepted_seq if self.master_fb is not None else 0
        return seqs.index(accepted) + 1 if accepted in seqs else 0

    # --------------------------------------------------------------- the loop
    def send_raw(self, raw: bytes) -> Any:
        self.t += self.period
        self.call(None, raw)
        return self.prog.step(self.t)

    def loop(self, n: int = 1) -> Any:
        fb = None
        for _ in range(n):
            self.t += self.period
            if self.exchanging and self.slave.state is SlaveState.DATA_EXCH:
                if self.stream:
                    self.record = self.streamed_record()
                reply = self.call(None, self.encode(self.record))
                try:
                    self.master_fb = self.decode(reply.data)
                except ProtocolError:            # the image before the program's first loop
                    assert not any(reply.data)
            fb = self.prog.step(self.t)
            self.trace.append((self.t, fb, self.arm.joints))
            self.observe()
        assert fb is not None
        return fb

    def until(self, pred: Callable[[Any], bool], max_time: float = 30.0) -> Any:
        end = self.t + max_time
        fb = self.loop()
        while not pred(fb):
            assert self.t < end, "condition not reached within %.1f s of fake time" % max_time
            fb = self.loop()
        return fb

    def run_stream(self, slots: Sequence[Any], max_time: float = 60.0) -> Any:
        self.stream = list(slots)
        last = slots[-1].seq
        return self.until(lambda fb: fb.done_seq == last and fb.state in (StreamState.IDLE, StreamState.WAITING)
                          and not self.arm.moving, max_time)
