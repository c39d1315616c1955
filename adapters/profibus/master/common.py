"""What the parts of the master share: a request on the line, a DP-V1 job, a slave's turn.

Plain records and tables; the behaviour is in the parts (:mod:`.line`, :mod:`.station`,
:mod:`.scheduler`, :mod:`.acyclic`) and their composition (:mod:`.engine`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

from adapters.profibus.codec import dpv1
from adapters.profibus.codec.fdl import DataTelegram, ResponseFc, ResponseStatus, ShortAck
from adapters.profibus.master.events import Purpose

MAX_TURN: Final = 4  # telegrams of one slave in one cycle (retries not counted)

Reply = DataTelegram | ShortAck


@dataclass
class Job:
    """A DP-V1 read or write queued for one slave (1.10)."""

    id: int
    address: int
    request: dpv1.ReadRequest | dpv1.WriteRequest
    deadline: float
    requested: bool = False  # the request was accepted: poll for the answer


@dataclass(slots=True)
class Turn:
    """What a slave had in its turn of this cycle (the scheduler's bookkeeping)."""

    count: int = 0
    data: bool = False
    diag: bool = False
    ready_polls: int = 0
    acyclic: int = 0
    acyclic_wait: bool = False  # the slave has nothing for us yet: next turn


@dataclass(slots=True)
class Pending:
    """A request on the line, or waiting for its repetition (1.1)."""

    address: int
    purpose: Purpose
    data: bytes
    sent_at: float
    deadline: float
    max_tries: int
    fcb_function: bool
    tries: int = 1
    garbled: bool = False
    job: Job | None = None
    dsap: int | None = None  # the request's DSAP: the reply's SSAP must match (1.2)
    written: bool = False  # the driver confirmed the write (Written): the deadline counts


SHORT_ACK_PURPOSES: Final = frozenset(
    {Purpose.SET_PRM, Purpose.CHK_CFG, Purpose.RECORD, Purpose.POLL}
)  # requests that E5 may answer (Data_Exchange: only a slave without inputs)
DPV1_PURPOSES: Final = frozenset({Purpose.RECORD, Purpose.POLL})
REQUEST_NAMES: Final[Mapping[Purpose, str]] = {
    Purpose.DIAG: "Slave_Diag",
    Purpose.SET_PRM: "Set_Prm",
    Purpose.CHK_CFG: "Chk_Cfg",
    Purpose.GET_CFG: "Get_Cfg",
    Purpose.DATA: "Data_Exchange",
    Purpose.RECORD: "a DP-V1 request",
    Purpose.POLL: "a DP-V1 poll",
    Purpose.STATUS: "FDL status",
}

DATA_OK: Final = frozenset(
    {
        ResponseStatus.OK,
        ResponseStatus.DL,
        ResponseStatus.DH,
        ResponseStatus.RDL,
        ResponseStatus.RDH,
    }
)


def status_of(t: Reply) -> ResponseStatus | None:
    """The response status of a reply; a short acknowledgement counts as OK."""
    if isinstance(t, ShortAck):
        return ResponseStatus.OK
    return t.fc.status if isinstance(t.fc, ResponseFc) else None


def show(t: Reply) -> str:
    if isinstance(t, ShortAck):
        return "a short acknowledgement"
    status = status_of(t)
    name = status.name if status is not None else "?"
    sap = "without SAP" if t.ssap is None else f"from SAP {t.ssap}"
    return f"{name} {sap} with {len(t.data)} bytes"
