"""DP-V0 services: SAPs, Set_Prm, Global_Control, Set_Slave_Add, Data_Exchange, dispatch.

Sans-IO codec written from the fact sheet (``reference/protocol-facts.md``): 1.4 SAP map and
service types, 1.5 start-up steps, 1.6 Set_Prm data, 1.9 Global_Control. Chk_Cfg/Get_Cfg
identifiers live in :mod:`.cfg` (1.7), Slave_Diag in :mod:`.diag` (1.8). Every PDU is a
frozen dataclass with ``encode() -> bytes`` and a ``decode(data)`` classmethod.

The same code serves both ends of the wire:

* master engine: :func:`build_request` (PDU -> :class:`DataTelegram` with the right SAPs) and
  :func:`decode_response` (a slave's reply, keyed by its SSAP);
* slave simulator: :func:`decode_request` (keyed by DSAP) and :func:`build_response`
  (swaps addresses and SAPs).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar, Final, Self

from adapters.profibus.codec.chkcfg import Configuration
from adapters.profibus.codec.diag import SlaveDiag
from adapters.profibus.codec.fdl import (
    BROADCAST,
    MAX_DU,
    DataTelegram,
    RequestFc,
    RequestFunction,
    ResponseStatus,
    StationType,
)
from adapters.profibus.codec.pdu import bit, bits, exact, fail, need
from adapters.profibus.errors import DecodeFailure, require_length
from gateway.errors import FrameEncodeError, require_int


class SlaveSap(IntEnum):
    """Slave destination SAPs (fact sheet 1.4). Data_Exchange uses no SAP at all."""

    MSAC_C2_RM = 49  # MSAC_C2 resource manager (Initiate)
    ALARM_ACK = 50  # MSAC_C1 alarm acknowledge
    MSAC_C1 = 51  # MSAC_C1 read/write
    EXT_USER_PRM = 53  # ◐
    SET_SLAVE_ADD = 55
    RD_INP = 56
    RD_OUTP = 57
    GLOBAL_CONTROL = 58
    GET_CFG = 59
    SLAVE_DIAG = 60
    SET_PRM = 61
    CHK_CFG = 62


class MasterSap(IntEnum):
    """Master source SAPs (fact sheet 1.4)."""

    MS2 = 50  # class 2
    MS1 = 51  # class 1 acyclic (MSAC_C1)
    MASTER_MASTER = 54
    MS0 = 62  # all DP-V0 services


MAX_DATA_EXCHANGE: Final = 246  # 1.2: at most 246 bytes follow FC (no SAPs on Data_Exchange)

# ---------------------------------------------------------------------------------------
# Set_Prm (fact sheet 1.6)

# Watchdog base (1.6): T_WD = 10 ms x F1 x F2, or 1 ms x F1 x F2 with WD_Base_1ms.
WD_BASE_10MS: Final = 0.010
WD_BASE_1MS: Final = 0.001
WD_FACTOR_MAX: Final = 255
ALARM_MODE_MAX_ALARMS: Final = (1, 2, 4, 8, 12, 16, 24, 32)  # 1.6: byte 9 b0-2


def watchdog_factors(timeout: float, *, base_1ms: bool = False) -> tuple[int, int]:
    """WD_Fact_1, WD_Fact_2 (1..255 each) for a watchdog of at least ``timeout`` seconds.

    Picks the smallest product ``F1 x F2 >= timeout / base`` (so the watchdog is never shorter
    than asked), then the smallest F1. 100 ms at 10 ms base -> (1, 10) (fact sheet 1.6
    example). Raises FrameEncodeError outside base .. 65025 x base (650.25 s at 10 ms).
    """
    base = WD_BASE_1MS if base_1ms else WD_BASE_10MS
    if not math.isfinite(timeout) or timeout <= 0:
        raise FrameEncodeError(f"watchdog time must be positive, got {timeout!r}")
    units = max(1, math.ceil(round(timeout / base, 6)))
    if units > WD_FACTOR_MAX * WD_FACTOR_MAX:
        raise FrameEncodeError(f"watchdog time {timeout} s exceeds 65025 x {base} s")
    best: tuple[int, int] | None = None
    for f1 in range(max(1, math.ceil(units / WD_FACTOR_MAX)), WD_FACTOR_MAX + 1):
        f2 = math.ceil(units / f1)
        if f2 <= WD_FACTOR_MAX and (best is None or f1 * f2 < best[0] * best[1]):
            best = (f1, f2)
        if f1 * f1 >= units:  # beyond the square root only mirrors of what was tried
            break
    if best is None:  # pragma: no cover - units <= 65025 always has a pair
        raise FrameEncodeError(f"no watchdog factors for {timeout} s")
    return best


def watchdog_time(f1: int, f2: int, *, base_1ms: bool = False) -> float:
    """Watchdog time in seconds for the factors (fact sheet 1.6)."""
    return (WD_BASE_1MS if base_1ms else WD_BASE_10MS) * f1 * f2


@dataclass(frozen=True)
class Dpv1Status:
    """Set_Prm bytes 7-9, DPV1_Status_1..3 (fact sheet 1.6); reserved bits are ignored."""

    # DPV1_Status_1 (byte 7)
    dpv1_enable: bool = True  # b7, must be 1 before MSAC_C1 works
    fail_safe: bool = False  # b6
    publisher_enable: bool = False  # b5
    wd_base_1ms: bool = False  # b2
    dis_stop_control: bool = False  # b1
    dis_start_control: bool = False  # b0
    # DPV1_Status_2 (byte 8)
    chk_cfg_mode: bool = False  # b0
    update_alarm: bool = False  # b2
    status_alarm: bool = False  # b3
    manufacturer_alarm: bool = False  # b4
    diagnostic_alarm: bool = False  # b5
    process_alarm: bool = False  # b6
    pull_plug_alarm: bool = False  # b7
    # DPV1_Status_3 (byte 9)
    alarm_mode: int = 0  # b0-2: 0..7 = 1, 2, 4, 8, 12, 16, 24, 32 alarms
    prm_structure: bool = False  # b3
    isom_req: bool = False  # b4
    prm_cmd: bool = False  # b7

    @property
    def max_alarms(self) -> int:
        return ALARM_MODE_MAX_ALARMS[self.alarm_mode & 0x07]

    def encode(self) -> bytes:
        require_int("alarm_mode", self.alarm_mode, 0, 7)
        return bytes(
            (
                bits(
                    (self.dpv1_enable, 7),
                    (self.fail_safe, 6),
                    (self.publisher_enable, 5),
                    (self.wd_base_1ms, 2),
                    (self.dis_stop_control, 1),
                    (self.dis_start_control, 0),
                ),
                bits(
                    (self.chk_cfg_mode, 0),
                    (self.update_alarm, 2),
                    (self.status_alarm, 3),
                    (self.manufacturer_alarm, 4),
                    (self.diagnostic_alarm, 5),
                    (self.process_alarm, 6),
                    (self.pull_plug_alarm, 7),
                ),
                self.alarm_mode
                | bits((self.prm_structure, 3), (self.isom_req, 4), (self.prm_cmd, 7)),
            )
        )

    @classmethod
    def decode(cls, data: bytes) -> Self:
        exact(data, 3, "DPV1_Status")
        s1, s2, s3 = data
        return cls(
            dpv1_enable=bit(s1, 7),
            fail_safe=bit(s1, 6),
            publisher_enable=bit(s1, 5),
            wd_base_1ms=bit(s1, 2),
            dis_stop_control=bit(s1, 1),
            dis_start_control=bit(s1, 0),
            chk_cfg_mode=bit(s2, 0),
            update_alarm=bit(s2, 2),
            status_alarm=bit(s2, 3),
            manufacturer_alarm=bit(s2, 4),
            diagnostic_alarm=bit(s2, 5),
            process_alarm=bit(s2, 6),
            pull_plug_alarm=bit(s2, 7),
            alarm_mode=s3 & 0x07,
            prm_structure=bit(s3, 3),
            isom_req=bit(s3, 4),
            prm_cmd=bit(s3, 7),
        )


@dataclass(frozen=True)
class SetPrm:
    """Set_Prm data to SAP 61 (fact sheet 1.6).

    ``dpv1`` holds bytes 7-9 for a DP-V1 slave; with ``None`` (DP-V0 layout) ``user_prm_data``
    starts at byte 7. Which layout applies is the slave's (GSD) business, so
    :meth:`decode` takes ``dpv1=``. Station_Status bits 0-2 are reserved and ignored.
    """

    ident_number: int
    lock_req: bool = True  # b7 (Lock 1 / Unlock 0 = locked to this master, the normal case)
    unlock_req: bool = False  # b6
    sync_req: bool = False  # b5
    freeze_req: bool = False  # b4
    wd_on: bool = False  # b3
    wd_fact_1: int = 1  # byte 1, 1..255
    wd_fact_2: int = 1  # byte 2, 1..255
    min_tsdr: int = 0  # byte 3, 0 = unchanged
    group_ident: int = 0  # byte 6, bit n = group n+1
    dpv1: Dpv1Status | None = None
    user_prm_data: bytes = b""

    @property
    def watchdog_time(self) -> float:
        """Watchdog time in seconds (1 ms base when DPV1 WD_Base_1ms is set)."""
        base_1ms = self.dpv1 is not None and self.dpv1.wd_base_1ms
        return watchdog_time(self.wd_fact_1, self.wd_fact_2, base_1ms=base_1ms)

    def encode(self) -> bytes:
        require_int("ident_number", self.ident_number, 0, 0xFFFF)
        head = bytes(
            (
                bits(
                    (self.wd_on, 3),
                    (self.freeze_req, 4),
                    (self.sync_req, 5),
                    (self.unlock_req, 6),
                    (self.lock_req, 7),
                ),
                require_int("wd_fact_1", self.wd_fact_1, 1, WD_FACTOR_MAX),
                require_int("wd_fact_2", self.wd_fact_2, 1, WD_FACTOR_MAX),
                require_int("min_tsdr", self.min_tsdr, 0, 255),
                self.ident_number >> 8,
                self.ident_number & 0xFF,
                require_int("group_ident", self.group_ident, 0, 255),
            )
        )
        dpv1 = self.dpv1.encode() if self.dpv1 is not None else b""
        user = require_length("user_prm_data", self.user_prm_data, 0, MAX_DU - 7 - len(dpv1))
        return head + dpv1 + user

    @classmethod
    def decode(cls, data: bytes, *, dpv1: bool = False) -> Self:
        data = bytes(data)
        need(data, 10 if dpv1 else 7, "Set_Prm")
        status = data[0]
        if data[1] == 0 or data[2] == 0:
            raise fail(DecodeFailure.BAD_FIELD, "watchdog factor 0 (allowed 1..255)", data)
        return cls(
            ident_number=data[4] << 8 | data[5],
            lock_req=bit(status, 7),
            unlock_req=bit(status, 6),
            sync_req=bit(status, 5),
            freeze_req=bit(status, 4),
            wd_on=bit(status, 3),
            wd_fact_1=data[1],
            wd_fact_2=data[2],
            min_tsdr=data[3],
            group_ident=data[6],
            dpv1=Dpv1Status.decode(data[7:10]) if dpv1 else None,
            user_prm_data=data[10:] if dpv1 else data[7:],
        )


# ---------------------------------------------------------------------------------------
# Global_Control (fact sheet 1.9)


@dataclass(frozen=True)
class GlobalControl:
    """Global_Control data ``[Control_Command, Group_Select]`` (fact sheet 1.9).

    Control_Command b1 Clear_Data, b2 Unfreeze, b3 Freeze, b4 Unsync, b5 Sync (other bits
    reserved, ignored). Group_Select 0 = all slaves, bit n = group n+1.
    """

    clear_data: bool = False
    unfreeze: bool = False
    freeze: bool = False
    unsync: bool = False
    sync: bool = False
    group_select: int = 0

    @classmethod
    def operate(cls, group_select: int = 0) -> Self:
        return cls(group_select=group_select)

    @classmethod
    def clear(cls, group_select: int = 0) -> Self:
        return cls(clear_data=True, group_select=group_select)

    @staticmethod
    def groups_mask(groups: Iterable[int]) -> int:
        """Group_Select for groups numbered 1..8."""
        return sum(1 << (require_int("group", g, 1, 8) - 1) for g in set(groups))

    def encode(self) -> bytes:
        return bytes(
            (
                bits(
                    (self.clear_data, 1),
                    (self.unfreeze, 2),
                    (self.freeze, 3),
                    (self.unsync, 4),
                    (self.sync, 5),
                ),
                require_int("group_select", self.group_select, 0, 255),
            )
        )

    @classmethod
    def decode(cls, data: bytes) -> Self:
        data = bytes(data)
        exact(data, 2, "Global_Control")
        cmd = data[0]
        return cls(bit(cmd, 1), bit(cmd, 2), bit(cmd, 3), bit(cmd, 4), bit(cmd, 5), data[1])


# ---------------------------------------------------------------------------------------
# Set_Slave_Add, data PDUs and empty requests


@dataclass(frozen=True)
class SetSlaveAdd:
    """Set_Slave_Add data [new address, Ident high, Ident low, No_Add_Chg, user data] (◐)."""

    new_address: int
    ident_number: int
    no_add_chg: bool = False
    user_data: bytes = b""

    def encode(self) -> bytes:
        require_int("ident_number", self.ident_number, 0, 0xFFFF)
        return bytes(
            (
                require_int("new_address", self.new_address, 0, BROADCAST),
                self.ident_number >> 8,
                self.ident_number & 0xFF,
                1 if self.no_add_chg else 0,
            )
        ) + require_length("user data", self.user_data, 0, MAX_DU - 4)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        data = bytes(data)
        need(data, 4, "Set_Slave_Add")
        if data[0] > BROADCAST:
            raise fail(DecodeFailure.BAD_FIELD, f"new address {data[0]}", data)
        return cls(data[0], data[1] << 8 | data[2], data[3] != 0, data[4:])


@dataclass(frozen=True)
class DataExchange:
    """Data_Exchange request: the master's outputs, sent without SAPs (fact sheet 1.5 step 6)."""

    outputs: bytes = b""

    def encode(self) -> bytes:
        return require_length("outputs", self.outputs, 0, MAX_DATA_EXCHANGE)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        return cls(bytes(data))


@dataclass(frozen=True)
class InputData:
    """A slave's inputs: Data_Exchange response (no SAPs) or Rd_Inp response (SSAP 56)."""

    inputs: bytes = b""

    def encode(self) -> bytes:
        return require_length("inputs", self.inputs, 0, MAX_DATA_EXCHANGE)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        return cls(bytes(data))


@dataclass(frozen=True)
class OutputData:
    """Rd_Outp response (SSAP 57): the outputs the slave holds."""

    outputs: bytes = b""

    def encode(self) -> bytes:
        return require_length("outputs", self.outputs, 0, MAX_DU)

    @classmethod
    def decode(cls, data: bytes) -> Self:
        return cls(bytes(data))


class _EmptyRequest:
    """A request without data (Slave_Diag, Get_Cfg, Rd_Inp, Rd_Outp)."""

    what: ClassVar[str] = "request"

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode(cls, data: bytes) -> Self:
        data = bytes(data)
        exact(data, 0, cls.what)
        return cls()


@dataclass(frozen=True)
class SlaveDiagRequest(_EmptyRequest):
    what: ClassVar[str] = "Slave_Diag request"


@dataclass(frozen=True)
class GetCfgRequest(_EmptyRequest):
    what: ClassVar[str] = "Get_Cfg request"


@dataclass(frozen=True)
class ReadInputsRequest(_EmptyRequest):
    what: ClassVar[str] = "Rd_Inp request"


@dataclass(frozen=True)
class ReadOutputsRequest(_EmptyRequest):
    what: ClassVar[str] = "Rd_Outp request"


# ---------------------------------------------------------------------------------------
# Telegram level: SAP dispatch for master and simulator

DpRequest = (
    DataExchange
    | SetSlaveAdd
    | ReadInputsRequest
    | ReadOutputsRequest
    | GlobalControl
    | GetCfgRequest
    | SlaveDiagRequest
    | SetPrm
    | Configuration
)
DpResponse = InputData | OutputData | Configuration | SlaveDiag

# 1.4: which DSAP each request goes to (None = no address extension, Data_Exchange).
REQUEST_SAP: Final[dict[type, SlaveSap | None]] = {
    DataExchange: None,
    SetSlaveAdd: SlaveSap.SET_SLAVE_ADD,
    ReadInputsRequest: SlaveSap.RD_INP,
    ReadOutputsRequest: SlaveSap.RD_OUTP,
    GlobalControl: SlaveSap.GLOBAL_CONTROL,
    GetCfgRequest: SlaveSap.GET_CFG,
    SlaveDiagRequest: SlaveSap.SLAVE_DIAG,
    SetPrm: SlaveSap.SET_PRM,
    Configuration: SlaveSap.CHK_CFG,
}

# 1.4: which function each request uses by default (pyprofibus: SRD-high for all SRDs;
# Global_Control is SDN to 127).
REQUEST_FUNCTION: Final[dict[type, RequestFunction]] = {
    **{t: RequestFunction.SRD_HIGH for t in REQUEST_SAP},
    GlobalControl: RequestFunction.SDN_HIGH,
}


def _decode_set_prm(data: bytes, dpv1: bool) -> DpRequest:
    return SetPrm.decode(data, dpv1=dpv1)


def _plain(decoder: Callable[[bytes], DpRequest]) -> Callable[[bytes, bool], DpRequest]:
    return lambda data, _dpv1: decoder(data)


_REQUEST_DECODERS: Final[dict[int | None, Callable[[bytes, bool], DpRequest]]] = {
    None: _plain(DataExchange.decode),
    SlaveSap.SET_SLAVE_ADD: _plain(SetSlaveAdd.decode),
    SlaveSap.RD_INP: _plain(ReadInputsRequest.decode),
    SlaveSap.RD_OUTP: _plain(ReadOutputsRequest.decode),
    SlaveSap.GLOBAL_CONTROL: _plain(GlobalControl.decode),
    SlaveSap.GET_CFG: _plain(GetCfgRequest.decode),
    SlaveSap.SLAVE_DIAG: _plain(SlaveDiagRequest.decode),
    SlaveSap.SET_PRM: _decode_set_prm,
    SlaveSap.CHK_CFG: _plain(Configuration.decode),
}


def _decode_diag(data: bytes, dpv1: bool) -> DpResponse:
    return SlaveDiag.decode(data, dpv1=dpv1)


def _decode_get_cfg(data: bytes, _dpv1: bool) -> DpResponse:
    return Configuration.decode(data, allow_skip_check=False)


_RESPONSE_DECODERS: Final[dict[int | None, Callable[[bytes, bool], DpResponse]]] = {
    None: lambda data, _dpv1: InputData.decode(data),
    SlaveSap.RD_INP: lambda data, _dpv1: InputData.decode(data),
    SlaveSap.RD_OUTP: lambda data, _dpv1: OutputData.decode(data),
    SlaveSap.GET_CFG: _decode_get_cfg,
    SlaveSap.SLAVE_DIAG: _decode_diag,
}


def request_sap(pdu: DpRequest) -> SlaveSap | None:
    """The DSAP a request goes to (None for Data_Exchange)."""
    try:
        return REQUEST_SAP[type(pdu)]
    except KeyError:
        raise FrameEncodeError(f"not a DP request PDU: {pdu!r}") from None


def build_request(pdu: DpRequest, *, da: int, sa: int, fc: RequestFc | None = None) -> DataTelegram:
    """The request telegram for ``pdu`` from master ``sa`` to slave ``da`` (fact sheet 1.4).

    ``fc`` defaults to the service's function without FCB (use :class:`FcbState` ``.fc()``
    for SRDs); Global_Control defaults to SDN and should go to ``da=BROADCAST``.
    """
    dsap = request_sap(pdu)
    if fc is None:
        fc = RequestFc(REQUEST_FUNCTION[type(pdu)])
    ssap = MasterSap.MS0 if dsap is not None else None
    return DataTelegram(da, sa, fc, dsap, ssap, pdu.encode())


def decode_request(telegram: DataTelegram, *, dpv1: bool = False) -> DpRequest:
    """Simulator side: decode a request by its DSAP; ``dpv1`` selects the Set_Prm layout."""
    decoder = _REQUEST_DECODERS.get(telegram.dsap)
    if decoder is None or not telegram.is_request:
        raise fail(
            DecodeFailure.UNKNOWN_FUNCTION,
            f"no DP-V0 request on DSAP {telegram.dsap} ({telegram.fc!r})",
            telegram.data,
        )
    return decoder(telegram.data, dpv1)


def build_response(
    pdu: DpResponse,
    *,
    request: DataTelegram,
    status: ResponseStatus = ResponseStatus.DL,
    station_type: StationType = StationType.SLAVE,
) -> DataTelegram:
    """Simulator side: the reply to ``request`` (addresses and SAPs swapped, fact sheet 1.2)."""
    return request.reply(pdu.encode(), status, station_type)


def decode_response(telegram: DataTelegram, *, dpv1: bool = False) -> DpResponse:
    """Master side: decode a slave's data reply by its SSAP; ``dpv1`` for alarm/status blocks.

    A short acknowledgement (E5) is not a :class:`DataTelegram`; the engine handles it.
    """
    decoder = _RESPONSE_DECODERS.get(telegram.ssap)
    if decoder is None or telegram.is_request:
        raise fail(
            DecodeFailure.UNKNOWN_FUNCTION,
            f"no DP-V0 response from SSAP {telegram.ssap} ({telegram.fc!r})",
            telegram.data,
        )
    return decoder(telegram.data, dpv1)


def global_control_request(control: GlobalControl, *, sa: int, da: int = BROADCAST) -> DataTelegram:
    """Global_Control: SDN to 127, DSAP 58, SSAP 62, FCB inactive (fact sheet 1.9)."""
    return build_request(control, da=da, sa=sa, fc=RequestFc(RequestFunction.SDN_HIGH))
