"""What goes in and out of the master engine: states, events, actions, slave parameters.

The engine (:mod:`.master`) is stepped with :data:`Event` values (what the line delivered)
and returns :data:`Action` values (telegrams to send, and what happened to the slaves).
:class:`SlaveParams` is what the master sends one slave at start-up (fact sheet 1.6, 1.7).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from adapters.profibus.codec import dpv1
from adapters.profibus.codec.chkcfg import Configuration
from adapters.profibus.codec.diag import SlaveDiag
from adapters.profibus.codec.dp import Dpv1Status, SetPrm, watchdog_factors
from adapters.profibus.codec.fdl import MAX_STATION, DataTelegram, ShortAck, TokenTelegram
from adapters.profibus.errors import FdlDecodeError, ProfibusDecodeError
from gateway.errors import FrameEncodeError


class SlaveState(Enum):
    """Where the master is with one slave (fact sheet 1.5 master steps)."""

    __hash__ = object.__hash__  # members are their own identity: a C hash, not Enum's

    WAIT_DIAG = "wait_diag"  # step 2: Slave_Diag until a valid reply
    SET_PRM = "set_prm"  # step 3
    CHK_CFG = "chk_cfg"  # step 4
    WAIT_READY = "wait_ready"  # step 5: Slave_Diag until ready
    GET_CFG = "get_cfg"  # after Cfg_Fault: read the slave's own configuration
    DATA_EXCHANGE = "data_exchange"  # step 6
    ABSENT = "absent"  # no reply: probed every absent_retry
    FAULT = "fault"  # Cfg_Fault, Prm_Fault, locked...: started again every fault_retry


class LineMode(Enum):
    """What Global_Control tells the slaves (fact sheet 1.9), and what outputs they get."""

    __hash__ = object.__hash__  # members are their own identity: a C hash, not Enum's

    OPERATE = "operate"
    CLEAR = "clear"  # Clear_Data; outputs all zero (1.5 step 6)


class Purpose(Enum):
    """What a request on the line is for."""

    __hash__ = object.__hash__  # members are their own identity: a C hash, not Enum's

    DIAG = "diag"
    SET_PRM = "set_prm"
    CHK_CFG = "chk_cfg"
    GET_CFG = "get_cfg"
    DATA = "data"
    RECORD = "record"  # DP-V1 read/write request
    POLL = "poll"  # DP-V1 poll for the answer
    STATUS = "status"  # FDL status request (live list)


class FaultKind(Enum):
    CFG_FAULT = "cfg_fault"
    PRM_FAULT = "prm_fault"
    NOT_SUPPORTED = "not_supported"
    LOCKED = "locked"  # parameterised by another master
    PRM_REQ_LOOP = "prm_req_loop"  # keeps asking for parameters
    NOT_READY = "not_ready"  # stays not ready after a good start-up
    REFUSED = "refused"  # Set_Prm/Chk_Cfg answered negatively at FDL level
    DPV1_UNANSWERED = "dpv1_unanswered"  # a DP-V1 telegram never answered (data exchange goes on)


class RecordFailure(Enum):
    TIMEOUT = "timeout"  # no answer within acyclic_timeout
    OFFLINE = "offline"  # the slave is not (or no more) in data exchange
    REFUSED = "refused"  # FDL-level refusal (RS: DP-V1 SAP not active)
    BAD_REPLY = "bad_reply"  # an answer that does not decode
    CANCELLED = "cancelled"


# ---------------------------------------------------------------------------------------
# Events in, actions out


@dataclass(frozen=True)
class FrameIn:
    """A telegram decoded off the line; ``raw``: its bytes when it came whole in one read
    (the steady lane compares a reply with the slave's last by them), else empty."""

    telegram: DataTelegram | ShortAck | TokenTelegram
    raw: bytes = b""


@dataclass(frozen=True)
class LineNoise:
    """Bytes that did not decode (the streaming decoder's ``Discarded``)."""

    error: FdlDecodeError


@dataclass(frozen=True)
class Receiving:
    """Bytes of a telegram arrived but the telegram is not complete yet."""


@dataclass(frozen=True)
class Written:
    """The driver wrote the oldest unconfirmed :class:`Transmit` to the port at ``at``.

    ``at`` is the driver's clock read after the write returned, not the time the engine
    planned: an event loop can run a callback late. The engine counts the line busy until
    the telegram's line time after ``at`` (fact sheet 1.1: bytes x 11 bit times; on a
    UART the bytes leave over that time once handed to the kernel), and every idle time
    and reply deadline from there. Until a Transmit is confirmed the engine sends nothing
    else and times nothing out.
    """

    at: float


Event = FrameIn | LineNoise | Receiving | Written


@dataclass(frozen=True)
class Transmit:
    """Send ``data`` at ``not_before`` at the earliest (the TSYN idle time is in it)."""

    data: bytes
    not_before: float
    expect_reply: bool = True


@dataclass(frozen=True)
class SlaveStateChanged:
    address: int
    old: SlaveState
    new: SlaveState


@dataclass(frozen=True)
class SlaveUp:
    """The slave entered data exchange."""

    address: int


@dataclass(frozen=True)
class SlaveDown:
    """The slave left data exchange (no reply, RS, asks for parameters again...)."""

    address: int
    reason: str


@dataclass(frozen=True)
class SlaveFault:
    """Start-up failed for a reason the slave gave (or the master saw), or DP-V1 to a slave
    in data exchange went unanswered: ``text`` says it."""

    address: int
    kind: FaultKind
    text: str
    slave_cfg: bytes | None = None  # Cfg_Fault: what Get_Cfg said the slave has


@dataclass(frozen=True)
class InputsReceived:
    address: int
    data: bytes


@dataclass(frozen=True)
class DiagnosisRead:
    """A Slave_Diag reply; ``ext`` holds the extended diagnosis bytes after the six."""

    address: int
    diag: SlaveDiag
    ext: bytes


@dataclass(frozen=True)
class RecordDone:
    """The end of a DP-V1 job: ``data`` (read data, b"" for a write), or why not."""

    job: int
    address: int
    data: bytes | None = None
    error: dpv1.Dpv1ErrorResponse | None = None
    failure: RecordFailure | None = None
    text: str = ""

    @property
    def ok(self) -> bool:
        return self.error is None and self.failure is None


Action = (
    Transmit
    | SlaveStateChanged
    | SlaveUp
    | SlaveDown
    | SlaveFault
    | InputsReceived
    | DiagnosisRead
    | RecordDone
)


# ---------------------------------------------------------------------------------------
# Configuration of one slave


@dataclass(frozen=True)
class SlaveParams:
    """What the master sends one slave at start-up and expects back (1.6, 1.7)."""

    address: int
    ident_number: int
    cfg: bytes
    user_prm: bytes = b""
    input_len: int = 0
    output_len: int = 0
    dpv1: bool = True
    group: int = 0  # Group_Ident bits
    watchdog: float | None = 0.5  # s; None = watchdog off
    origin: str = ""  # "GSD <file>, module '...'": named in Cfg_Fault / Prm_Fault events

    def set_prm(self, min_tsdr: int) -> SetPrm:
        """The Set_Prm PDU: locked to this master, watchdog, min TSDR, DP-V1 bytes (1.6)."""
        wd_on = self.watchdog is not None and self.watchdog > 0
        f1, f2 = watchdog_factors(self.watchdog) if wd_on and self.watchdog else (1, 1)
        return SetPrm(
            ident_number=self.ident_number,
            lock_req=True,
            wd_on=wd_on,
            wd_fact_1=f1,
            wd_fact_2=f2,
            min_tsdr=min_tsdr,
            group_ident=self.group,
            dpv1=Dpv1Status(dpv1_enable=True) if self.dpv1 else None,
            user_prm_data=self.user_prm,
        )


def check_slave(params: SlaveParams, master_address: int) -> None:
    """FrameEncodeError if the slave cannot be run by this master."""
    if not 0 <= params.address <= MAX_STATION:
        raise FrameEncodeError(f"slave address {params.address} is outside 0..{MAX_STATION}")
    if params.address == master_address:
        raise FrameEncodeError(f"slave address {params.address} is the master's own")
    Configuration.decode(params.cfg, allow_skip_check=True)  # must at least decode


def describe_cfg(cfg: bytes) -> str:
    """``F1`` -> "F1 (4 bytes in, 4 bytes out)" (fact sheet 1.7)."""
    try:
        conf = Configuration.decode(cfg, allow_skip_check=True)
    except ProfibusDecodeError:
        return f"{cfg.hex(' ').upper() or 'empty'} (undecodable)"
    hexed = cfg.hex(" ").upper() or "empty"
    return f"{hexed} ({conf.input_bytes} bytes in, {conf.output_bytes} bytes out)"
