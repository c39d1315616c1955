"""The DeviceNet scanner engine (sans-IO, stepped with an injected clock).

``events`` holds the config, events and actions; ``engine`` the :class:`Scanner` (the line,
events in, deadlines, public API) and its parts: ``machine`` the per-node state machine,
``scheduler`` the poll cycle and the explicit and bring-up windows, ``jobs`` the explicit
message job queue, ``context`` what they share; ``node`` the per-node state. It imports
codecs only: no python-can, no asyncio (docs/architecture.md, "DeviceNet scanner").
"""

from adapters.can.events import (
    BadFrame,
    BusErrorIn,
    FrameIn,
    LinkDown,
    NodeUnavailable,
    Send,
    TxFailed,
)
from adapters.devicenet.scanner.engine import LinePhase, Scanner
from adapters.devicenet.scanner.events import (
    Action,
    Event,
    ExplicitResult,
    IdentityCheck,
    InputData,
    IoConflict,
    IoKind,
    LineFault,
    LineOnline,
    NodeConfig,
    NodeDown,
    NodeIdentity,
    NodeUp,
    Report,
    ReportKind,
    ScannerConfig,
)
from adapters.devicenet.scanner.node import Phase

__all__ = [
    "Action",
    "BadFrame",
    "BusErrorIn",
    "Event",
    "ExplicitResult",
    "FrameIn",
    "IdentityCheck",
    "InputData",
    "IoConflict",
    "IoKind",
    "LineFault",
    "LineOnline",
    "LinePhase",
    "LinkDown",
    "NodeConfig",
    "NodeDown",
    "NodeIdentity",
    "NodeUnavailable",
    "NodeUp",
    "Phase",
    "Report",
    "ReportKind",
    "Scanner",
    "ScannerConfig",
    "Send",
    "TxFailed",
]
