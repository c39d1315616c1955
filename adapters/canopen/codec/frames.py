"""CANopen frames, sans-IO: COB-IDs, NMT, SYNC, EMCY, heartbeat, SDO and PDO mapping.

CiA 301 §7.3.3 (pre-defined connection set: function code << 7 | node id), §7.2.8
(NMT services and the NMT state machine), §7.2.8.3.2 (heartbeat), §7.2.5 (SYNC),
§7.2.7 (EMCY), §7.2.4.3 (SDO protocols: initiate, segment, abort; the command
specifier in bits 7-5 of the first byte), §7.5.2.35-38 (PDO communication and
mapping parameters). The codec never imports python-can: a frame is a COB-ID and
0-8 data bytes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import Enum, IntEnum
from typing import ClassVar

from adapters.can import frame as can_frame
from adapters.can.frame import MAX_ARBITRATION_ID
from adapters.canopen.codec import codes
from adapters.canopen.errors import (
    CanOpenDecodeError,
    EmcyDecodeError,
    InvalidCobId,
    NmtDecodeError,
    SdoDecodeError,
    SdoProtocolError,
)
from gateway.errors import FrameDecodeError, FrameEncodeError, require_int

MAX_NODE_ID = 127
MAX_COB_ID = MAX_ARBITRATION_ID


class CanFrame(can_frame.CanFrame):
    """One classic CAN data frame: 11-bit COB-ID, 0-8 data bytes (CiA 301 uses the base
    frame format); :meth:`~CanFrame.from_bus` raises :class:`InvalidCobId` for what
    CANopen cannot carry."""

    __slots__ = ()
    invalid: ClassVar[type[FrameDecodeError]] = InvalidCobId

    @property
    def cob_id(self) -> int:
        """The identifier under its CANopen name."""
        return self.arbitration_id


# --- COB-IDs (CiA 301 §7.3.3, pre-defined connection set) ------------------------------


class Function(IntEnum):
    """Function codes of the pre-defined connection set (COB-ID bits 10-7)."""

    NMT = 0x0
    SYNC_EMCY = 0x1  # 0x080 SYNC, 0x081-0x0FF EMCY
    TIME = 0x2
    TPDO1 = 0x3
    RPDO1 = 0x4
    TPDO2 = 0x5
    RPDO2 = 0x6
    TPDO3 = 0x7
    RPDO3 = 0x8
    TPDO4 = 0x9
    RPDO4 = 0xA
    SDO_TX = 0xB  # server -> client, 0x580 + node
    SDO_RX = 0xC  # client -> server, 0x600 + node
    HEARTBEAT = 0xE  # NMT error control, 0x700 + node


COB_NMT = 0x000
COB_SYNC = 0x080
COB_TIME = 0x100
EMCY_BASE = 0x080
SDO_TX_BASE = 0x580
SDO_RX_BASE = 0x600
HEARTBEAT_BASE = 0x700
_TPDO_BASE = (0x180, 0x280, 0x380, 0x480)
_RPDO_BASE = (0x200, 0x300, 0x400, 0x500)


class Kind(Enum):
    """What a received COB-ID carries."""

    NMT = "nmt"
    SYNC = "sync"
    TIME = "time"
    EMCY = "emcy"
    TPDO = "tpdo"
    RPDO = "rpdo"
    SDO_TX = "sdo_tx"
    SDO_RX = "sdo_rx"
    HEARTBEAT = "heartbeat"


@dataclass(frozen=True, slots=True)
class CobId:
    """A decoded pre-defined COB-ID: its kind, the node (0 for broadcast objects) and
    the PDO number 1-4 (0 for other kinds)."""

    kind: Kind
    node_id: int = 0
    pdo: int = 0


def _node(node_id: int) -> int:
    return require_int("node id", node_id, 1, MAX_NODE_ID)


def _pdo_number(number: int) -> int:
    return require_int("PDO number", number, 1, 4)


def emcy_id(node_id: int) -> int:
    return EMCY_BASE + _node(node_id)


def tpdo_id(number: int, node_id: int) -> int:
    """COB-ID of TPDO ``number`` (1-4) of a node (the node transmits it)."""
    return _TPDO_BASE[_pdo_number(number) - 1] + _node(node_id)


def rpdo_id(number: int, node_id: int) -> int:
    """COB-ID of RPDO ``number`` (1-4) of a node (the node receives it)."""
    return _RPDO_BASE[_pdo_number(number) - 1] + _node(node_id)


def sdo_tx_id(node_id: int) -> int:
    """Server -> client SDO (the node answers on 0x580 + id)."""
    return SDO_TX_BASE + _node(node_id)


def sdo_rx_id(node_id: int) -> int:
    """Client -> server SDO (the node listens on 0x600 + id)."""
    return SDO_RX_BASE + _node(node_id)


def heartbeat_id(node_id: int) -> int:
    return HEARTBEAT_BASE + _node(node_id)


def classify(cob_id: int) -> CobId:
    """The kind, node and PDO number of a pre-defined COB-ID; :class:`InvalidCobId`
    for an identifier outside the pre-defined set."""
    if isinstance(cob_id, bool) or not isinstance(cob_id, int) or not 0 <= cob_id <= MAX_COB_ID:
        raise InvalidCobId(f"identifier {cob_id!r} is not 11-bit")
    function, node = cob_id >> 7, cob_id & 0x7F
    if cob_id == COB_NMT:
        return CobId(Kind.NMT)
    if cob_id == COB_SYNC:
        return CobId(Kind.SYNC)
    if cob_id == COB_TIME:
        return CobId(Kind.TIME)
    if node == 0:
        raise InvalidCobId("node id 0 in a node-specific object", cob_id=cob_id)
    if function == Function.SYNC_EMCY:
        return CobId(Kind.EMCY, node)
    if Function.TPDO1 <= function <= Function.RPDO4:
        n = (function - Function.TPDO1) // 2 + 1
        kind = Kind.TPDO if (function - Function.TPDO1) % 2 == 0 else Kind.RPDO
        return CobId(kind, node, n)
    if function == Function.SDO_TX:
        return CobId(Kind.SDO_TX, node)
    if function == Function.SDO_RX:
        return CobId(Kind.SDO_RX, node)
    if function == Function.HEARTBEAT:
        return CobId(Kind.HEARTBEAT, node)
    raise InvalidCobId("not in the pre-defined connection set", cob_id=cob_id)


# --- NMT (CiA 301 §7.2.8) --------------------------------------------------------------


class NmtCommand(IntEnum):
    """NMT module control command specifiers (CiA 301 §7.2.8.3.1)."""

    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class NmtState(IntEnum):
    """NMT states as the heartbeat carries them (CiA 301 §7.2.8.3.2.3)."""

    BOOTUP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


@dataclass(frozen=True, slots=True)
class Nmt:
    """An NMT command to one node, or to all (``node_id`` 0)."""

    command: NmtCommand
    node_id: int = 0


def encode_nmt(command: NmtCommand, node_id: int = 0) -> CanFrame:
    """The NMT frame (COB-ID 0x000, 2 bytes: command, node id; 0 = all nodes)."""
    require_int("NMT node id", node_id, 0, MAX_NODE_ID)
    return CanFrame(COB_NMT, bytes((NmtCommand(command), node_id)))


def decode_nmt(data: bytes) -> Nmt:
    raw = bytes(data)
    if len(raw) != 2:
        raise NmtDecodeError(f"NMT command of {len(raw)} bytes (2 expected)", raw, cob_id=0)
    try:
        command = NmtCommand(raw[0])
    except ValueError:
        raise NmtDecodeError(f"unknown NMT command 0x{raw[0]:02X}", raw, cob_id=0) from None
    if raw[1] > MAX_NODE_ID:
        raise NmtDecodeError(f"NMT node id {raw[1]} out of 0..127", raw, cob_id=0)
    return Nmt(command, raw[1])


def encode_heartbeat(node_id: int, state: NmtState) -> CanFrame:
    """A heartbeat (or, with BOOTUP, the boot-up message): 0x700 + id, one state byte."""
    return CanFrame(heartbeat_id(node_id), bytes((NmtState(state),)))


def decode_heartbeat(data: bytes, *, cob_id: int | None = None) -> NmtState:
    """The state a heartbeat or boot-up frame carries (bit 7, the node guarding toggle,
    is ignored)."""
    raw = bytes(data)
    if len(raw) != 1:
        raise NmtDecodeError(f"heartbeat of {len(raw)} bytes (1 expected)", raw, cob_id=cob_id)
    try:
        return NmtState(raw[0] & 0x7F)
    except ValueError:
        raise NmtDecodeError(
            f"unknown NMT state 0x{raw[0] & 0x7F:02X}", raw, cob_id=cob_id
        ) from None


# --- SYNC (CiA 301 §7.2.5) -------------------------------------------------------------


def encode_sync(counter: int | None = None) -> CanFrame:
    """SYNC on 0x080: no data, or one counter byte 1-240 (CiA 301 §7.2.5.2.1)."""
    if counter is None:
        return CanFrame(COB_SYNC)
    return CanFrame(COB_SYNC, bytes((require_int("SYNC counter", counter, 1, 240),)))


# --- EMCY (CiA 301 §7.2.7) -------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Emcy:
    """An emergency message: error code (0 = error reset), error register (0x1001),
    five manufacturer-specific bytes."""

    error_code: int
    error_register: int
    manufacturer: bytes = bytes(5)

    @property
    def text(self) -> str:
        return codes.emcy_text(self.error_code)


def encode_emcy(node_id: int, emcy: Emcy) -> CanFrame:
    require_int("EMCY error code", emcy.error_code, 0, 0xFFFF)
    require_int("error register", emcy.error_register, 0, 0xFF)
    if len(emcy.manufacturer) > 5:
        raise FrameEncodeError("EMCY manufacturer field longer than 5 bytes")
    data = struct.pack("<HB", emcy.error_code, emcy.error_register) + emcy.manufacturer.ljust(
        5, b"\x00"
    )
    return CanFrame(emcy_id(node_id), data)


def decode_emcy(data: bytes, *, cob_id: int | None = None) -> Emcy:
    raw = bytes(data)
    if len(raw) != 8:
        raise EmcyDecodeError(f"EMCY of {len(raw)} bytes (8 expected)", raw, cob_id=cob_id)
    code, register = struct.unpack_from("<HB", raw)
    return Emcy(code, register, raw[3:])


# --- SDO (CiA 301 §7.2.4.3) ------------------------------------------------------------

# Client command specifiers (bits 7-5 of byte 0 of a request).
CCS_DOWNLOAD_SEGMENT = 0
CCS_INITIATE_DOWNLOAD = 1
CCS_INITIATE_UPLOAD = 2
CCS_UPLOAD_SEGMENT = 3
CCS_ABORT = 4
CCS_BLOCK_UPLOAD = 5
CCS_BLOCK_DOWNLOAD = 6
# Server command specifiers (bits 7-5 of byte 0 of a response).
SCS_UPLOAD_SEGMENT = 0
SCS_DOWNLOAD_SEGMENT = 1
SCS_INITIATE_UPLOAD = 2
SCS_INITIATE_DOWNLOAD = 3
SCS_ABORT = 4
SCS_BLOCK_DOWNLOAD = 5
SCS_BLOCK_UPLOAD = 6

SEGMENT_SIZE = 7


@dataclass(frozen=True, slots=True)
class InitiateDownload:
    """Client: write ``index:subindex``. Expedited when ``data`` (1-4 bytes) travels in
    this frame; else segmented, ``size`` announcing the bytes that follow (None = not
    indicated)."""

    index: int
    subindex: int
    data: bytes = b""
    expedited: bool = True
    size: int | None = None


@dataclass(frozen=True, slots=True)
class DownloadSegment:
    """Client: 1-7 bytes of a segmented write; ``last`` ends it (the c bit)."""

    toggle: bool
    data: bytes
    last: bool


@dataclass(frozen=True, slots=True)
class InitiateUpload:
    """Client: read ``index:subindex``."""

    index: int
    subindex: int


@dataclass(frozen=True, slots=True)
class UploadSegment:
    """Client: ask for the next segment of a segmented read."""

    toggle: bool


@dataclass(frozen=True, slots=True)
class Abort:
    """Either side: abort the transfer of ``index:subindex`` with a CiA 301 code."""

    index: int
    subindex: int
    code: int

    @property
    def text(self) -> str:
        return codes.abort_text(self.code)


@dataclass(frozen=True, slots=True)
class InitiateDownloadResponse:
    index: int
    subindex: int


@dataclass(frozen=True, slots=True)
class DownloadSegmentResponse:
    toggle: bool


@dataclass(frozen=True, slots=True)
class InitiateUploadResponse:
    """Server: expedited with ``data`` (1-4 bytes; 4 when the size is not indicated), or
    segmented announcing ``size`` (None = not indicated)."""

    index: int
    subindex: int
    data: bytes = b""
    expedited: bool = True
    size: int | None = None


@dataclass(frozen=True, slots=True)
class UploadSegmentResponse:
    toggle: bool
    data: bytes
    last: bool


SdoRequest = InitiateDownload | DownloadSegment | InitiateUpload | UploadSegment | Abort
SdoResponse = (
    InitiateDownloadResponse
    | DownloadSegmentResponse
    | InitiateUploadResponse
    | UploadSegmentResponse
    | Abort
)


def _mux(index: int, subindex: int) -> bytes:
    require_int("object index", index, 0, 0xFFFF)
    require_int("subindex", subindex, 0, 0xFF)
    return struct.pack("<HB", index, subindex)


def _initiate(cs: int, message: InitiateDownload | InitiateUploadResponse) -> bytes:
    data, expedited, size = bytes(message.data), message.expedited, message.size
    mux = _mux(message.index, message.subindex)
    if expedited:
        if not 1 <= len(data) <= 4:
            raise FrameEncodeError(f"expedited SDO data of {len(data)} bytes (1-4)")
        n = 4 - len(data)
        return bytes(((cs << 5) | (n << 2) | 0x03,)) + mux + data.ljust(4, b"\x00")
    if data:
        raise FrameEncodeError("a segmented SDO initiate carries no data, only its size")
    if size is None:
        return bytes((cs << 5,)) + mux + bytes(4)
    require_int("SDO size", size, 0, 0xFFFFFFFF)
    return bytes(((cs << 5) | 0x01,)) + mux + struct.pack("<I", size)


def _segment(cs: int, toggle: bool, data: bytes, last: bool) -> bytes:
    if len(data) > SEGMENT_SIZE:
        raise FrameEncodeError(f"SDO segment of {len(data)} bytes (at most 7)")
    if not data and not last:
        raise FrameEncodeError("an SDO segment other than the last carries at least 1 byte")
    n = SEGMENT_SIZE - len(data)
    first = (cs << 5) | (0x10 if toggle else 0) | (n << 1) | (0x01 if last else 0)
    return bytes((first,)) + data.ljust(SEGMENT_SIZE, b"\x00")


def _abort(message: Abort) -> bytes:
    require_int("SDO abort code", message.code, 0, 0xFFFFFFFF)
    return (
        bytes((CCS_ABORT << 5,))
        + _mux(message.index, message.subindex)
        + struct.pack("<I", message.code)
    )


def encode_sdo_request(message: SdoRequest) -> bytes:
    """The 8 data bytes of a client -> server SDO frame (COB-ID 0x600 + node)."""
    if isinstance(message, InitiateDownload):
        return _initiate(CCS_INITIATE_DOWNLOAD, message)
    if isinstance(message, DownloadSegment):
        return _segment(CCS_DOWNLOAD_SEGMENT, message.toggle, bytes(message.data), message.last)
    if isinstance(message, InitiateUpload):
        return bytes((CCS_INITIATE_UPLOAD << 5,)) + _mux(message.index, message.subindex) + bytes(4)
    if isinstance(message, UploadSegment):
        return bytes(((CCS_UPLOAD_SEGMENT << 5) | (0x10 if message.toggle else 0),)) + bytes(7)
    return _abort(message)


def encode_sdo_response(message: SdoResponse) -> bytes:
    """The 8 data bytes of a server -> client SDO frame (COB-ID 0x580 + node)."""
    if isinstance(message, InitiateDownloadResponse):
        return (
            bytes((SCS_INITIATE_DOWNLOAD << 5,)) + _mux(message.index, message.subindex) + bytes(4)
        )
    if isinstance(message, DownloadSegmentResponse):
        return bytes(((SCS_DOWNLOAD_SEGMENT << 5) | (0x10 if message.toggle else 0),)) + bytes(7)
    if isinstance(message, InitiateUploadResponse):
        return _initiate(SCS_INITIATE_UPLOAD, message)
    if isinstance(message, UploadSegmentResponse):
        return _segment(SCS_UPLOAD_SEGMENT, message.toggle, bytes(message.data), message.last)
    return _abort(message)


def _check_len(raw: bytes, cob_id: int | None) -> None:
    if len(raw) != 8:
        raise SdoDecodeError(f"SDO frame of {len(raw)} bytes (8 expected)", raw, cob_id=cob_id)


def _decode_initiate(raw: bytes, cob_id: int | None) -> tuple[int, int, bytes, bool, int | None]:
    index, subindex = struct.unpack_from("<HB", raw, 1)
    expedited, size_indicated = bool(raw[0] & 0x02), bool(raw[0] & 0x01)
    if expedited:
        n = (raw[0] >> 2) & 0x03 if size_indicated else 0
        return index, subindex, raw[4 : 8 - n], True, None
    if raw[0] & 0x0C:
        raise SdoDecodeError("segmented SDO initiate with n bits set", raw, cob_id=cob_id)
    size = struct.unpack_from("<I", raw, 4)[0] if size_indicated else None
    return index, subindex, b"", False, size


def _decode_segment(raw: bytes, cob_id: int | None) -> tuple[bool, bytes, bool]:
    toggle, last = bool(raw[0] & 0x10), bool(raw[0] & 0x01)
    n = (raw[0] >> 1) & 0x07
    if n == SEGMENT_SIZE and not last:
        raise SdoDecodeError("SDO segment without data that is not the last", raw, cob_id=cob_id)
    return toggle, raw[1 : 8 - n], last


def _decode_abort(raw: bytes) -> Abort:
    index, subindex, code = struct.unpack_from("<HBI", raw, 1)
    return Abort(index, subindex, code)


def decode_sdo_request(data: bytes, *, cob_id: int | None = None) -> SdoRequest:
    """A client -> server SDO frame; block transfers are an :class:`SdoDecodeError`
    (answer it with abort 0x05040001)."""
    raw = bytes(data)
    _check_len(raw, cob_id)
    ccs = raw[0] >> 5
    if ccs == CCS_INITIATE_DOWNLOAD:
        index, subindex, payload, expedited, size = _decode_initiate(raw, cob_id)
        return InitiateDownload(index, subindex, payload, expedited, size)
    if ccs == CCS_DOWNLOAD_SEGMENT:
        return DownloadSegment(*_decode_segment(raw, cob_id))
    if ccs == CCS_INITIATE_UPLOAD:
        index, subindex = struct.unpack_from("<HB", raw, 1)
        return InitiateUpload(index, subindex)
    if ccs == CCS_UPLOAD_SEGMENT:
        return UploadSegment(bool(raw[0] & 0x10))
    if ccs == CCS_ABORT:
        return _decode_abort(raw)
    raise SdoDecodeError(f"client command specifier {ccs} not supported", raw, cob_id=cob_id)


def decode_sdo_response(data: bytes, *, cob_id: int | None = None) -> SdoResponse:
    """A server -> client SDO frame."""
    raw = bytes(data)
    _check_len(raw, cob_id)
    scs = raw[0] >> 5
    if scs == SCS_INITIATE_DOWNLOAD:
        index, subindex = struct.unpack_from("<HB", raw, 1)
        return InitiateDownloadResponse(index, subindex)
    if scs == SCS_DOWNLOAD_SEGMENT:
        return DownloadSegmentResponse(bool(raw[0] & 0x10))
    if scs == SCS_INITIATE_UPLOAD:
        index, subindex, payload, expedited, size = _decode_initiate(raw, cob_id)
        return InitiateUploadResponse(index, subindex, payload, expedited, size)
    if scs == SCS_UPLOAD_SEGMENT:
        return UploadSegmentResponse(*_decode_segment(raw, cob_id))
    if scs == SCS_ABORT:
        return _decode_abort(raw)
    raise SdoDecodeError(f"server command specifier {scs} not supported", raw, cob_id=cob_id)


# --- SDO client transfers (sans-IO) ---------------------------------------------------


@dataclass(frozen=True, slots=True)
class SdoResult:
    """The end of a transfer: the bytes read (empty for a write), or the abort code
    (the server's, or the client's own when the server broke the protocol) and
    whether the server sent it."""

    data: bytes = b""
    abort_code: int | None = None
    by_server: bool = False

    @property
    def ok(self) -> bool:
        return self.abort_code is None

    @property
    def message(self) -> str:
        return "ok" if self.abort_code is None else codes.abort_message(self.abort_code)


class SdoClientTransfer:
    """One SDO client transfer, expedited or segmented, upload or download.

    ``first()`` gives the first request's bytes; each server response goes to
    ``on_response(data)``, which returns the next request's bytes (a segment, or the
    client's abort when the response breaks the protocol) or None. When ``result`` is
    set the transfer is over. Timeouts are the caller's (abort with 0x05040000 via
    :meth:`timeout`).

    A response that cannot answer the request outstanding is not this transfer's and is
    ignored (``ignored`` counts them; ``on_response`` returns None, ``result`` stays
    None): before the initiate response, one naming another index/sub-index (CiA 301
    §7.2.4.3.3-6: an initiate response names the object), one of the other direction, a
    segment response; at any time, an abort naming another object. Such a frame is the
    late answer of a transfer the client already ended on its timeout (and aborted): taken
    as this transfer's, it would end it with 0x05040001 (command specifier not valid).
    """

    def __init__(self, index: int, subindex: int, write: bytes | None = None) -> None:
        _mux(index, subindex)
        self.index = index
        self.subindex = subindex
        self.write = None if write is None else bytes(write)
        self._toggle = False
        self._offset = 0
        self._received = bytearray()
        self._size: int | None = None
        self.result: SdoResult | None = None
        self.ignored = 0  # responses not this transfer's (see the class docstring)

    @property
    def is_upload(self) -> bool:
        return self.write is None

    def first(self) -> bytes:
        if self.write is None:
            return encode_sdo_request(InitiateUpload(self.index, self.subindex))
        if 1 <= len(self.write) <= 4:
            return encode_sdo_request(InitiateDownload(self.index, self.subindex, self.write))
        return encode_sdo_request(
            InitiateDownload(self.index, self.subindex, b"", expedited=False, size=len(self.write))
        )

    def timeout(self) -> bytes:
        """End the transfer on the caller's timeout; returns the abort to send."""
        return self._client_abort(codes.ABORT_TIMEOUT)

    def _client_abort(self, code: int) -> bytes:
        self.result = SdoResult(abort_code=code)
        return encode_sdo_request(Abort(self.index, self.subindex, code))

    def on_response(self, data: bytes) -> bytes | None:
        if self.result is not None:
            return None
        try:
            response = decode_sdo_response(data)
        except SdoDecodeError:
            return self._client_abort(codes.ABORT_COMMAND)
        if not self._is_ours(response):
            self.ignored += 1
            return None
        if isinstance(response, Abort):
            self.result = SdoResult(abort_code=response.code, by_server=True)
            return None
        try:
            return self._next(response)
        except SdoProtocolError as error:
            return self._client_abort(error.abort_code)

    def _is_ours(self, response: SdoResponse) -> bool:
        """False for a frame that cannot answer the request outstanding (a late answer
        of an earlier transfer); a protocol error of the server is still ours."""
        if isinstance(response, Abort):
            # a server that names no object (0x0000) is taken at its word
            mux = (response.index, response.subindex)
            return response.index == 0 or mux == (self.index, self.subindex)
        if self._offset != 0 or self._received:
            return True  # segments under way: checked by the protocol
        if self.write is None:
            if not isinstance(response, InitiateUploadResponse):
                return False
        elif not isinstance(response, InitiateDownloadResponse):
            return False
        return (response.index, response.subindex) == (self.index, self.subindex)

    def _expect_mux(self, index: int, subindex: int) -> None:
        if (index, subindex) != (self.index, self.subindex):
            raise SdoProtocolError(
                f"response for 0x{index:04X}:{subindex} to a request for "
                f"0x{self.index:04X}:{self.subindex}",
                abort_code=codes.ABORT_COMMAND,
            )

    def _next(self, response: SdoResponse) -> bytes | None:
        if self.write is None:
            return self._next_upload(response)
        return self._next_download(response, self.write)

    def _next_upload(self, response: SdoResponse) -> bytes | None:
        if (
            isinstance(response, InitiateUploadResponse)
            and self._offset == 0
            and not self._received
        ):
            self._expect_mux(response.index, response.subindex)
            if response.expedited:
                self.result = SdoResult(bytes(response.data))
                return None
            self._size = response.size
            self._offset = 1  # segments under way
            return encode_sdo_request(UploadSegment(self._toggle))
        if isinstance(response, UploadSegmentResponse) and self._offset == 1:
            if response.toggle != self._toggle:
                raise SdoProtocolError("toggle bit not alternated", abort_code=codes.ABORT_TOGGLE)
            self._received += response.data
            if response.last:
                if self._size is not None and self._size != len(self._received):
                    raise SdoProtocolError(
                        f"{len(self._received)} bytes read, {self._size} announced",
                        abort_code=codes.ABORT_LENGTH,
                    )
                self.result = SdoResult(bytes(self._received))
                return None
            self._toggle = not self._toggle
            return encode_sdo_request(UploadSegment(self._toggle))
        raise SdoProtocolError(
            f"unexpected {type(response).__name__} in an upload", abort_code=codes.ABORT_COMMAND
        )

    def _next_download(self, response: SdoResponse, payload: bytes) -> bytes | None:
        if isinstance(response, InitiateDownloadResponse) and self._offset == 0:
            self._expect_mux(response.index, response.subindex)
            if len(payload) <= 4 and payload:
                self.result = SdoResult()
                return None
            return self._send_segment(payload)
        if isinstance(response, DownloadSegmentResponse) and self._offset > 0:
            if response.toggle != self._toggle:
                raise SdoProtocolError("toggle bit not alternated", abort_code=codes.ABORT_TOGGLE)
            if self._offset >= len(payload):
                self.result = SdoResult()
                return None
            self._toggle = not self._toggle
            return self._send_segment(payload)
        raise SdoProtocolError(
            f"unexpected {type(response).__name__} in a download", abort_code=codes.ABORT_COMMAND
        )

    def _send_segment(self, payload: bytes) -> bytes:
        chunk = payload[self._offset : self._offset + SEGMENT_SIZE]
        self._offset += len(chunk)
        if not chunk:  # an empty write: one empty last segment
            self._offset = 1
        return encode_sdo_request(
            DownloadSegment(self._toggle, chunk, last=self._offset >= len(payload))
        )


# --- PDO parameters (CiA 301 §7.5.2.35-38) ---------------------------------------------

RPDO_COMM_BASE = 0x1400
RPDO_MAP_BASE = 0x1600
TPDO_COMM_BASE = 0x1800
TPDO_MAP_BASE = 0x1A00
PDO_COB_INVALID = 0x80000000  # bit 31 of sub 1: PDO does not exist / is not valid
PDO_NO_RTR = 0x40000000  # bit 30 (TPDO): no RTR allowed
TRANSMISSION_SYNC = 0x01  # synchronous, every SYNC
TRANSMISSION_EVENT = 0xFF  # event-driven (device profile)


@dataclass(frozen=True, slots=True)
class MappingEntry:
    """One PDO mapping entry: object index, subindex, length in bits."""

    index: int
    subindex: int
    bits: int

    def encode(self) -> int:
        """The UNSIGNED32 of the mapping object: index << 16 | subindex << 8 | bits."""
        require_int("mapped index", self.index, 0, 0xFFFF)
        require_int("mapped subindex", self.subindex, 0, 0xFF)
        require_int("mapped length", self.bits, 1, 64)
        return (self.index << 16) | (self.subindex << 8) | self.bits

    @classmethod
    def decode(cls, value: int) -> MappingEntry:
        return cls((value >> 16) & 0xFFFF, (value >> 8) & 0xFF, value & 0xFF)


def unpack_pdo(entries: tuple[MappingEntry, ...], data: bytes) -> tuple[bytes, ...]:
    """Split a PDO's data into the raw little-endian bytes of its byte-aligned entries;
    :class:`CanOpenDecodeError` if it is shorter than the mapping."""
    raw = bytes(data)
    out: list[bytes] = []
    offset = 0
    for entry in entries:
        size = entry.bits // 8
        if offset + size > len(raw):
            raise CanOpenDecodeError(
                f"PDO of {len(raw)} bytes, mapping needs {sum(e.bits for e in entries) // 8}",
                raw,
            )
        out.append(raw[offset : offset + size])
        offset += size
    return tuple(out)
