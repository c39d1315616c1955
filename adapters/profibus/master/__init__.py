"""The Profibus DP class-1 master engine: sans-IO, stepped with an injected clock.

Written from the fact sheet (``reference/protocol-facts.md``): 1.1 timing (TSYN before every
request, TSL bounding each wait, retries), 1.3 FCB handling, 1.5 start-up and error handling,
1.6 Set_Prm, 1.7 Chk_Cfg/Get_Cfg, 1.8 Slave_Diag, 1.9 Global_Control, 1.10 DP-V1 MSAC_C1.

:class:`Master` (:mod:`.engine`) is what the adapter and the driver use: ``step(now, event)
-> actions`` and ``next_deadline()``, commands as plain method calls. It is the composition
of four parts, each stepped through it with the same clock:

- :mod:`.station`: one :class:`~.station.Station` per DP slave, the per-station state
  machine (Slave_Diag, Set_Prm, Chk_Cfg, Get_Cfg, data exchange, loss and recovery, state
  timeouts); it decides what a reply or a diagnosis means for the slave.
- :mod:`.scheduler`: which station is served when (the cycle, each station's turn, the
  line tasks: Sync/Freeze, the Operate/Clear broadcast, the live-list probe).
- :mod:`.acyclic`: the DP-V1 job queue (reads and writes, their deadlines, the back-off
  after an unanswered request).
- :mod:`.line`: one request outstanding on the line, the idle time before the next, the
  reply wait and the repetition of a request (1.1), all counted from the time the driver
  confirms a write.
"""

from __future__ import annotations

from adapters.profibus.master.acyclic import DPV1_BACKOFF, MAX_ACYCLIC_PER_TURN
from adapters.profibus.master.common import MAX_TURN
from adapters.profibus.master.engine import Master
from adapters.profibus.master.events import (
    Action,
    DiagnosisRead,
    Event,
    FaultKind,
    FrameIn,
    InputsReceived,
    LineMode,
    LineNoise,
    Purpose,
    Receiving,
    RecordDone,
    RecordFailure,
    SlaveDown,
    SlaveFault,
    SlaveParams,
    SlaveState,
    SlaveStateChanged,
    SlaveUp,
    Transmit,
    Written,
    check_slave,
    describe_cfg,
)
from adapters.profibus.master.scheduler import IDLE_GUARD
from adapters.profibus.master.station import FRAME_MEMO, MAX_PRM_ATTEMPTS, STATE_TIMEOUTS

__all__ = [
    "DPV1_BACKOFF",
    "FRAME_MEMO",
    "IDLE_GUARD",
    "MAX_ACYCLIC_PER_TURN",
    "MAX_PRM_ATTEMPTS",
    "MAX_TURN",
    "STATE_TIMEOUTS",
    "Action",
    "DiagnosisRead",
    "Event",
    "FaultKind",
    "FrameIn",
    "InputsReceived",
    "LineMode",
    "LineNoise",
    "Master",
    "Purpose",
    "Receiving",
    "RecordDone",
    "RecordFailure",
    "SlaveDown",
    "SlaveFault",
    "SlaveParams",
    "SlaveState",
    "SlaveStateChanged",
    "SlaveUp",
    "Transmit",
    "Written",
    "check_slave",
    "describe_cfg",
]
