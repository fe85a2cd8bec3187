"""pyprofibus_vendor: a ROS-free PROFIBUS-DP stack (PHY, FDL, DP master class 1, DP slave, GSD)."""
from __future__ import annotations

from .errors import (ConfigError, DpError, DpTimeoutError, FcsError, FdlError, FdlTimeoutError,
                     FrameError, GsdError, PhyError, PhyTimeoutError, ProfibusError,
                     TruncatedFrameError)
from .phy import FaultCounters, FaultyLink, Link, MemoryLink
from .phy_serial import FdLink, PtyPair, SerialLink, is_pty, open_pty_pair
from .fdl import (BROADCAST, Deframer, FcbRequester, FcbResponder, Frame, FrameControl,
                  RequestFunction, ResponseStatus, Sd1, Sd2, Sd3, Sd4, ShortAck, StationType,
                  data_frame, decode_frame)
from .dp import (MASTER_SAP, ChkCfg, DataExchange, DiagStatus1, DiagStatus2, DiagStatus3,
                 GcCommand, GetCfg, GlobalControl, PrmStationStatus, Sap, SetPrm, SetSlaveAdd,
                 SlaveDiag, cfg_io_lengths, explain_diag, watchdog_factors)
from .dp_master import (AcyclicRequest, BusTiming, DpMaster, MasterCounters, MasterSlaveState,
                        SlaveHandle, SlaveSpec)
from .dp_slave import DpSlave, SlaveLink, SlaveServer, SlaveState

__all__ = [
    # errors
    "ProfibusError", "PhyError", "PhyTimeoutError", "FdlError", "FrameError", "FcsError",
    "TruncatedFrameError", "FdlTimeoutError", "DpError", "DpTimeoutError", "ConfigError",
    "GsdError",
    # PHY
    "Link", "MemoryLink", "FaultyLink", "FaultCounters", "SerialLink", "FdLink", "PtyPair",
    "open_pty_pair", "is_pty",
    # FDL
    "BROADCAST", "Frame", "FrameControl", "RequestFunction", "ResponseStatus", "StationType",
    "Sd1", "Sd2", "Sd3", "Sd4", "ShortAck", "data_frame", "decode_frame", "Deframer",
    "FcbRequester", "FcbResponder",
    # DP
    "MASTER_SAP", "Sap", "DiagStatus1", "DiagStatus2", "DiagStatus3", "PrmStationStatus",
    "GcCommand", "SlaveDiag", "SetPrm", "ChkCfg", "GetCfg", "DataExchange", "GlobalControl",
    "SetSlaveAdd", "cfg_io_lengths", "explain_diag", "watchdog_factors",
    # master / slave
    "DpMaster", "SlaveSpec", "SlaveHandle", "MasterSlaveState", "MasterCounters", "BusTiming",
    "AcyclicRequest", "DpSlave", "SlaveState", "SlaveServer", "SlaveLink",
]
