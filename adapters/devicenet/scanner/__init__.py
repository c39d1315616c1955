"""The DeviceNet scanner engine (sans-IO, stepped with an injected clock).

``api`` holds the config, events and actions; ``engine`` the :class:`Scanner`;
``node`` its per-node state. It imports codecs only: no python-can, no asyncio.
"""

from adapters.devicenet.scanner.api import (
    Action,
    BadFrame,
    BusErrorIn,
    Event,
    ExplicitResult,
    FrameIn,
    IdentityCheck,
    InputData,
    IoKind,
    LineFault,
    LineOnline,
    LinkDown,
    NodeConfig,
    NodeDown,
    NodeIdentity,
    NodeUnavailable,
    NodeUp,
    Report,
    ReportKind,
    ScannerConfig,
    Send,
    TxFailed,
)
from adapters.devicenet.scanner.engine import LinePhase, Scanner
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
