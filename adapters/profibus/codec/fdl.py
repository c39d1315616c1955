"""FDL telegrams: SD1, SD2, SD3, SD4, short acknowledgement, FCS, SAPs, frame control, FCB.

Sans-IO codec of the Profibus data link layer, written from the fact sheet
(``reference/protocol-facts.md``): 1.2 frame formats, length and checksum rules, address
extension; 1.3 frame-control byte, request functions, response status codes, FCB handling.

* :class:`DataTelegram` is SD1, SD2 or SD3 (the encoder picks the delimiter from the length),
  :class:`TokenTelegram` is SD4, :class:`ShortAck` is SC 0xE5.
* :func:`decode_telegram` decodes exactly one telegram; :class:`TelegramDecoder` is the
  streaming decoder for bytes as they come off the line (see its docstring).
* :class:`FcbState` is the master's FCB/FCV per slave; :class:`SlaveFcbMemory` is the
  slave-side repeat detection for a simulator.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from enum import Enum, IntEnum
from typing import Final

from adapters.profibus.errors import DecodeFailure, FdlDecodeError, require_length
from gateway.errors import FrameEncodeError, require_int

# 1.2 start delimiters and end delimiter.
SD1: Final = 0x10
SD2: Final = 0x68
SD3: Final = 0xA2
SD4: Final = 0xDC
SC: Final = 0xE5
ED: Final = 0x16


class StartDelimiter(IntEnum):
    """First byte of each telegram type (fact sheet 1.2)."""

    SD1 = 0x10  # fixed length, no data: 10 DA SA FC FCS 16
    SD2 = 0x68  # variable length: 68 LE LEr 68 DA SA FC [DSAP SSAP] DU FCS 16
    SD3 = 0xA2  # fixed length, 8 data bytes (SAPs included): A2 DA SA FC D*8 FCS 16
    SD4 = 0xDC  # token: DC DA SA
    SC = 0xE5  # short acknowledgement


BROADCAST: Final = 127  # 1.2: address 127 = broadcast
MAX_STATION: Final = 125  # 1.2: station addresses must be <= 125
DEFAULT_SLAVE_ADDRESS: Final = 126  # address of a slave waiting for Set_Slave_Add
MIN_LE: Final = 3  # 1.2: pyprofibus accepts LE 3..249
MAX_LE: Final = 249
MAX_DATA_AFTER_FC: Final = 246  # 1.2: at most 246 bytes follow FC (SAP bytes included)
MAX_DU: Final = 244  # 1.2: so up to 244 bytes of user data fit after DSAP and SSAP
SD3_LENGTH: Final = 8  # 1.2: SD3 carries 8 bytes after FC, SAPs included
_ADDRESS_EXT: Final = 0x80  # 1.2: bit 7 of DA / SA = a DSAP / SSAP byte follows FC
_SAP_EXTRA_BITS: Final = 0xC0  # 1.2: extension byte b7 = another extension, b6 = segment
MAX_SAP: Final = 63  # 1.2: extension byte bits 5-0 = value


class RequestFunction(IntEnum):
    """FC bits 3-0 of a request (fact sheet 1.3, request function codes)."""

    TIME_EVENT = 0x0
    SDA_LOW = 0x3
    SDN_LOW = 0x4
    SDA_HIGH = 0x5
    SDN_HIGH = 0x6
    SRD_MULTICAST = 0x7
    FDL_STATUS = 0x9
    SRD_LOW = 0xC
    SRD_HIGH = 0xD
    IDENT = 0xE
    LSAP_STATUS = 0xF


# 1.3: the FCB is used on acknowledged services (SRD, SDA), never on SDN or broadcast.
FCB_FUNCTIONS: Final = frozenset(
    {
        RequestFunction.SDA_LOW,
        RequestFunction.SDA_HIGH,
        RequestFunction.SRD_LOW,
        RequestFunction.SRD_HIGH,
        RequestFunction.SRD_MULTICAST,
    }
)


class ResponseStatus(IntEnum):
    """FC bits 3-0 of a response (fact sheet 1.3, response status codes)."""

    OK = 0x0
    UE = 0x1  # user error
    RR = 0x2  # no resources
    RS = 0x3  # SAP not activated
    DL = 0x8  # data low
    NR = 0x9  # no data
    DH = 0xA  # data high (DP: diagnosis waiting)
    RDL = 0xC
    RDH = 0xD


class StationType(IntEnum):
    """FC bits 5-4 of a response (fact sheet 1.3)."""

    SLAVE = 0b00
    MASTER_NOT_READY = 0b01
    MASTER_READY = 0b10
    MASTER_IN_RING = 0b11


_FC_RESERVED: Final = 0x80  # 1.3: b7 = 0
_FC_REQUEST: Final = 0x40  # 1.3: b6 = 1 request, 0 response
_FC_FCB: Final = 0x20  # 1.3: request b5
_FC_FCV: Final = 0x10  # 1.3: request b4


@dataclass(frozen=True)
class RequestFc:
    """Frame control of a request: function, FCB and FCV (fact sheet 1.3)."""

    function: RequestFunction
    fcb: bool = False
    fcv: bool = False

    @property
    def is_request(self) -> bool:
        return True

    def encode(self) -> int:
        return (
            _FC_REQUEST
            | (_FC_FCB if self.fcb else 0)
            | (_FC_FCV if self.fcv else 0)
            | RequestFunction(self.function)
        )


@dataclass(frozen=True)
class ResponseFc:
    """Frame control of a response: station type and status (fact sheet 1.3)."""

    status: ResponseStatus
    station_type: StationType = StationType.SLAVE

    @property
    def is_request(self) -> bool:
        return False

    def encode(self) -> int:
        return (StationType(self.station_type) << 4) | ResponseStatus(self.status)


FrameControl = RequestFc | ResponseFc


def decode_fc(value: int, raw: bytes = b"") -> FrameControl:
    """Decode an FC byte; reserved bit or unknown code -> FdlDecodeError (fact sheet 1.3)."""
    if value & _FC_RESERVED:
        raise FdlDecodeError(
            DecodeFailure.BAD_FRAME_CONTROL, f"FC 0x{value:02X}: reserved bit 7 set", raw
        )
    code = value & 0x0F
    try:
        if value & _FC_REQUEST:
            return RequestFc(RequestFunction(code), bool(value & _FC_FCB), bool(value & _FC_FCV))
        return ResponseFc(ResponseStatus(code), StationType((value >> 4) & 0x03))
    except ValueError:
        kind = "request function" if value & _FC_REQUEST else "response status"
        raise FdlDecodeError(
            DecodeFailure.BAD_FRAME_CONTROL, f"FC 0x{value:02X}: unknown {kind} {code:#x}", raw
        ) from None


@dataclass(frozen=True)
class DataTelegram:
    """An SD1, SD2 or SD3 telegram (fact sheet 1.2).

    ``dsap``/``ssap`` are ``None`` when the address extension bit is clear; ``data`` is the
    DU after the SAP bytes. Whether it is a request or a response follows from ``fc``.
    """

    da: int
    sa: int
    fc: FrameControl
    dsap: int | None = None
    ssap: int | None = None
    data: bytes = b""

    @property
    def is_request(self) -> bool:
        return self.fc.is_request

    @property
    def length(self) -> int:
        """LE: bytes from DA to the end of DU, SAP bytes included (fact sheet 1.2)."""
        return 3 + (self.dsap is not None) + (self.ssap is not None) + len(self.data)

    @property
    def delimiter(self) -> StartDelimiter:
        """SD1 when LE = 3, SD3 when LE = 11, otherwise SD2 (fact sheet 1.2)."""
        return _DELIMITER_BY_LENGTH.get(self.length, StartDelimiter.SD2)

    def reply(
        self,
        data: bytes = b"",
        status: ResponseStatus = ResponseStatus.DL,
        station_type: StationType = StationType.SLAVE,
    ) -> DataTelegram:
        """The response to this request: addresses and SAPs swapped (fact sheet 1.2)."""
        return DataTelegram(
            self.sa, self.da, ResponseFc(status, station_type), self.ssap, self.dsap, data
        )

    def encode(self) -> bytes:
        require_int("DA", self.da, 0, BROADCAST)
        require_int("SA", self.sa, 0, BROADCAST)
        body = bytearray(
            (
                self.da | (_ADDRESS_EXT if self.dsap is not None else 0),
                self.sa | (_ADDRESS_EXT if self.ssap is not None else 0),
                _encode_fc(self.fc),
            )
        )
        for name, sap in (("DSAP", self.dsap), ("SSAP", self.ssap)):
            if sap is not None:
                body.append(require_int(name, sap, 0, MAX_SAP))
        body += require_length("DU", self.data, 0, MAX_DATA_AFTER_FC - (len(body) - 3))
        fcs = sum(body) & 0xFF
        delimiter = self.delimiter
        if delimiter is StartDelimiter.SD2:
            return bytes((SD2, len(body), len(body), SD2, *body, fcs, ED))
        return bytes((delimiter, *body, fcs, ED))


_DELIMITER_BY_LENGTH: Final = {3: StartDelimiter.SD1, 3 + SD3_LENGTH: StartDelimiter.SD3}


def _encode_fc(fc: FrameControl) -> int:
    if not isinstance(fc, RequestFc | ResponseFc):
        raise FrameEncodeError(f"FC must be RequestFc or ResponseFc, got {fc!r}")
    try:
        return fc.encode()
    except ValueError as exc:
        raise FrameEncodeError(f"bad frame control {fc!r}: {exc}") from None


@dataclass(frozen=True)
class TokenTelegram:
    """SD4 token telegram ``DC DA SA`` (fact sheet 1.2)."""

    da: int
    sa: int

    def encode(self) -> bytes:
        require_int("DA", self.da, 0, BROADCAST)
        require_int("SA", self.sa, 0, BROADCAST)
        return bytes((SD4, self.da, self.sa))


@dataclass(frozen=True)
class ShortAck:
    """The single-byte short acknowledgement SC ``E5`` (fact sheet 1.2)."""

    def encode(self) -> bytes:
        return bytes((SC,))


SHORT_ACK: Final = ShortAck()
Telegram = DataTelegram | TokenTelegram | ShortAck


def encode_telegram(telegram: Telegram) -> bytes:
    """Encode any telegram to its bytes on the line."""
    return telegram.encode()


def fcs(data: bytes) -> int:
    """Frame check sequence: sum of the bytes from DA to the end of DU, mod 256 (1.2)."""
    return sum(data) & 0xFF


# ---------------------------------------------------------------------------------------
# Decoding one telegram


def _fail(reason: DecodeFailure, message: str, raw: bytes) -> FdlDecodeError:
    return FdlDecodeError(reason, message, raw)


def _decode_body(body: bytes, checksum: int, raw: bytes) -> DataTelegram:
    """Decode DA SA FC [DSAP] [SSAP] DU, checking the FCS (fact sheet 1.2)."""
    if fcs(body) != checksum:
        raise _fail(
            DecodeFailure.BAD_CHECKSUM, f"FCS 0x{checksum:02X}, expected 0x{fcs(body):02X}", raw
        )
    da, sa, fc_byte = body[0], body[1], body[2]
    fc = decode_fc(fc_byte, raw)
    rest = body[3:]
    saps: list[int | None] = []
    for address in (da, sa):
        if not address & _ADDRESS_EXT:
            saps.append(None)
            continue
        if not rest:
            raise _fail(DecodeFailure.BAD_ADDRESS, "address extension without SAP byte", raw)
        if rest[0] & _SAP_EXTRA_BITS:
            raise _fail(
                DecodeFailure.BAD_ADDRESS,
                f"SAP byte 0x{rest[0]:02X}: segment/further extension not supported",
                raw,
            )
        saps.append(rest[0])
        rest = rest[1:]
    return DataTelegram(da & 0x7F, sa & 0x7F, fc, saps[0], saps[1], bytes(rest))


def _decode_fixed(raw: bytes, size: int) -> DataTelegram:
    """SD1 / SD3: SD DA SA FC [size-6 bytes] FCS ED."""
    if len(raw) != size:
        reason = DecodeFailure.TRUNCATED if len(raw) < size else DecodeFailure.TRAILING_BYTES
        raise _fail(reason, f"SD 0x{raw[0]:02X} telegram needs {size} bytes, got {len(raw)}", raw)
    _check_end(raw)
    return _decode_body(raw[1:-2], raw[-2], raw)


def _decode_sd1(raw: bytes) -> Telegram:
    return _decode_fixed(raw, 6)


def _decode_sd3(raw: bytes) -> Telegram:
    return _decode_fixed(raw, 6 + SD3_LENGTH)


def _decode_sd2(raw: bytes) -> Telegram:
    if len(raw) < 4:
        raise _fail(DecodeFailure.TRUNCATED, "SD2 header needs 4 bytes", raw)
    _check_sd2_header(raw[1], raw[2], raw[3], raw)
    size = raw[1] + 6
    if len(raw) != size:
        reason = DecodeFailure.TRUNCATED if len(raw) < size else DecodeFailure.TRAILING_BYTES
        raise _fail(reason, f"SD2 telegram with LE {raw[1]} needs {size} bytes", raw)
    _check_end(raw)
    return _decode_body(raw[4:-2], raw[-2], raw)


def _check_sd2_header(le: int, ler: int, sd: int, raw: bytes) -> None:
    if not MIN_LE <= le <= MAX_LE:
        raise _fail(DecodeFailure.BAD_LENGTH, f"LE {le} outside {MIN_LE}..{MAX_LE}", raw)
    if ler != le:
        raise _fail(DecodeFailure.BAD_LENGTH, f"LEr {ler} differs from LE {le}", raw)
    if sd != SD2:
        raise _fail(DecodeFailure.BAD_LENGTH, f"second SD2 is 0x{sd:02X}", raw)


def _check_end(raw: bytes) -> None:
    if raw[-1] != ED:
        raise _fail(DecodeFailure.BAD_END_DELIMITER, f"ED is 0x{raw[-1]:02X}, not 0x16", raw)


def _decode_sd4(raw: bytes) -> Telegram:
    if len(raw) != 3:
        reason = DecodeFailure.TRUNCATED if len(raw) < 3 else DecodeFailure.TRAILING_BYTES
        raise _fail(reason, f"SD4 telegram needs 3 bytes, got {len(raw)}", raw)
    if (raw[1] | raw[2]) & _ADDRESS_EXT:
        raise _fail(DecodeFailure.BAD_ADDRESS, "SD4 address above 127", raw)
    return TokenTelegram(raw[1], raw[2])


def _decode_sc(raw: bytes) -> Telegram:
    if len(raw) != 1:
        raise _fail(DecodeFailure.TRAILING_BYTES, "SC is a single byte", raw)
    return SHORT_ACK


_DECODERS: Final = {
    SD1: _decode_sd1,
    SD2: _decode_sd2,
    SD3: _decode_sd3,
    SD4: _decode_sd4,
    SC: _decode_sc,
}


def decode_telegram(raw: bytes) -> Telegram:
    """Decode exactly one telegram; anything else raises :class:`FdlDecodeError`."""
    raw = bytes(raw)
    if not raw:
        raise _fail(DecodeFailure.TRUNCATED, "no bytes", raw)
    decoder = _DECODERS.get(raw[0])
    if decoder is None:
        raise _fail(DecodeFailure.NO_START_DELIMITER, f"0x{raw[0]:02X} is no start delimiter", raw)
    return decoder(raw)


# ---------------------------------------------------------------------------------------
# Streaming decoder


class NeedMore(Enum):
    """Sentinel type of :data:`NEED_MORE`."""

    NEED_MORE = "need more"


NEED_MORE: Final = NeedMore.NEED_MORE


@dataclass(frozen=True)
class Discarded:
    """A run of bytes the streaming decoder skipped; ``error`` says why, ``error.raw`` what."""

    error: FdlDecodeError

    @property
    def raw(self) -> bytes:
        return self.error.raw


@dataclass(frozen=True)
class DecoderStats:
    """Counters of a :class:`TelegramDecoder` (snapshot)."""

    telegrams: int = 0
    telegram_bytes: int = 0  # bytes of the telegrams returned (bus load figures)
    discarded_bytes: int = 0
    decode_errors: int = 0  # one per Discarded event


DecoderEvent = DataTelegram | TokenTelegram | ShortAck | Discarded | NeedMore

DECODE_MEMO: Final = 256  # decoded telegrams a TelegramDecoder keeps by their bytes
_FIXED_SIZE: Final = {SD1: 6, SD3: 6 + SD3_LENGTH, SD4: 3, SC: 1}
_START_BYTES: Final = frozenset(_DECODERS)


class TelegramDecoder:
    """Streaming decoder: bytes in as they come, telegrams out (h11 ``next_event`` style).

    ``feed(data)`` appends bytes; ``next_frame()`` returns one event:

    * a :data:`Telegram` (request or response, see ``DataTelegram.is_request``),
    * :class:`Discarded` for a run of garbage skipped before the next good telegram (its
      error carries the first reason and the skipped bytes; counted in :attr:`stats`),
    * :data:`NEED_MORE` when the buffer holds no whole telegram yet.

    It never raises. After garbage it resynchronises byte by byte: a candidate that fails
    (bad header, FCS, ED, FC) loses only its first byte, so a good telegram inside the
    garbage is still found. ``mark_idle()`` tells it the line went idle (no gaps inside a
    telegram, and at least 33 idle bits before every request, fact sheet 1.1): no telegram
    may span that point, so a partial one before it is discarded instead of waiting for more.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self._base = 0  # stream offset of _buf[0]
        self._boundaries: deque[int] = deque()  # stream offsets of idle marks
        self._garbage = bytearray()
        self._garbage_error: FdlDecodeError | None = None
        self._telegrams = 0
        self._telegram_bytes = 0
        self._discarded_bytes = 0
        self._decode_errors = 0
        # Telegrams are immutable: the same bytes (a slave's unchanged inputs, cycle after
        # cycle) decode once. Only whole, valid telegrams are kept, at most DECODE_MEMO.
        self._memo: dict[bytes, Telegram] = {}

    @property
    def stats(self) -> DecoderStats:
        return DecoderStats(
            self._telegrams, self._telegram_bytes, self._discarded_bytes, self._decode_errors
        )

    @property
    def buffered(self) -> int:
        """Bytes held, not yet returned as a telegram or discarded."""
        return len(self._buf) + len(self._garbage)

    def feed(self, data: bytes) -> None:
        self._buf += data

    def whole(self, data: bytes) -> Telegram | None:
        """``data`` as one telegram, if nothing is buffered and it is one decoded before.

        The steady exchange's shortcut: a reply arrives in one read, and a slave's unchanged
        inputs are the bytes of its last reply. Counted as :meth:`next_frame` counts it;
        None (nothing taken): feed the bytes instead.
        """
        if self._buf or self._garbage:
            return None
        telegram = self._memo.get(data)
        if telegram is not None:
            self._base += len(data)
            self._telegrams += 1
            self._telegram_bytes += len(data)
        return telegram

    def mark_idle(self) -> None:
        """The line was idle after the bytes fed so far: no telegram spans this point."""
        end = self._base + len(self._buf)
        if self._buf and (not self._boundaries or self._boundaries[-1] != end):
            self._boundaries.append(end)

    def reset(self) -> None:
        """Drop everything buffered (e.g. after the port was reopened); keep the counters."""
        self._base += len(self._buf)
        self._buf.clear()
        self._boundaries.clear()
        self._garbage.clear()
        self._garbage_error = None

    def next_frame(self) -> DecoderEvent:
        while True:
            attempt = self._try_head()
            if attempt is NEED_MORE:
                return self._flush_garbage() or NEED_MORE
            if isinstance(attempt, FdlDecodeError):
                self._skip(self._skip_length(), attempt)
                continue
            telegram, size = attempt
            pending = self._flush_garbage()
            if pending is not None:
                return pending  # the telegram stays buffered and comes next call
            self._consume(size)
            self._telegrams += 1
            self._telegram_bytes += size
            return telegram

    # -- internals --------------------------------------------------------------------

    def _try_head(self) -> tuple[Telegram, int] | FdlDecodeError | NeedMore:
        buf = self._buf
        if not buf:
            return NEED_MORE
        first = buf[0]
        if first not in _START_BYTES:
            return _fail(
                DecodeFailure.NO_START_DELIMITER, f"0x{first:02X} is no start delimiter", b""
            )
        if first == SD2:
            size_or_error = self._sd2_size()
            if not isinstance(size_or_error, int):
                return size_or_error
            size = size_or_error
        else:
            size = _FIXED_SIZE[first]
        limit = self._limit()
        if limit is not None and size > limit:
            return _fail(DecodeFailure.TRUNCATED, "telegram cut short by an idle line", b"")
        if len(buf) < size:
            return NEED_MORE
        raw = bytes(buf[:size])
        known = self._memo.get(raw)
        if known is not None:
            return known, size
        try:
            telegram = decode_telegram(raw)
        except FdlDecodeError as exc:
            return exc
        if len(self._memo) >= DECODE_MEMO:
            self._memo.clear()
        self._memo[raw] = telegram
        return telegram, size

    def _sd2_size(self) -> int | FdlDecodeError | NeedMore:
        head = self._buf[:4]
        limit = self._limit()
        if len(head) < 4 and (limit is None or limit > len(head)):
            # check what has arrived, so a bad header fails without waiting
            checks = (
                len(head) >= 2 and not MIN_LE <= head[1] <= MAX_LE,
                len(head) >= 3 and head[2] != head[1],
            )
            if any(checks):
                return _fail(DecodeFailure.BAD_LENGTH, "bad SD2 header", b"")
            return NEED_MORE
        if len(head) < 4:
            return _fail(DecodeFailure.TRUNCATED, "SD2 header cut short by an idle line", b"")
        try:
            _check_sd2_header(head[1], head[2], head[3], b"")
        except FdlDecodeError as exc:
            return exc
        return head[1] + 6

    def _limit(self) -> int | None:
        """Bytes from the head up to the next idle mark, or None if there is none."""
        while self._boundaries and self._boundaries[0] <= self._base:
            self._boundaries.popleft()
        return self._boundaries[0] - self._base if self._boundaries else None

    def _skip_length(self) -> int:
        """Skip the failed start byte and every following byte that cannot start a telegram."""
        n = 1
        while n < len(self._buf) and self._buf[n] not in _START_BYTES:
            n += 1
        return n

    def _skip(self, n: int, error: FdlDecodeError) -> None:
        self._garbage += self._buf[:n]
        if self._garbage_error is None:
            self._garbage_error = error
        self._consume(n)

    def _consume(self, n: int) -> None:
        del self._buf[:n]
        self._base += n

    def _flush_garbage(self) -> Discarded | None:
        if not self._garbage or self._garbage_error is None:
            return None
        raw = bytes(self._garbage)
        first = self._garbage_error
        self._garbage.clear()
        self._garbage_error = None
        self._discarded_bytes += len(raw)
        self._decode_errors += 1
        return Discarded(FdlDecodeError(first.reason, first.message, raw))


# ---------------------------------------------------------------------------------------
# Frame count bit


@dataclass(frozen=True)
class FcbState:
    """Master-side FCB/FCV for one slave (fact sheet 1.3, "Frame count bit handling").

    After a reset FCB = 1, FCV = 0 (first SRD-high is 0x6D). After each acknowledged SRD or
    SDA call :meth:`acknowledged` (toggle FCB, set FCV = 1). On a retry keep the state.
    SDN and broadcast use :meth:`unsequenced` (FCB and FCV clear, e.g. 0x46).
    """

    fcb: bool = True
    fcv: bool = False

    def fc(self, function: RequestFunction) -> RequestFc:
        """FC for the next request; FCB functions carry the state, others carry none."""
        key = (function, self.fcb, self.fcv)
        fc = _FC_MEMO.get(key)
        if fc is None:  # RequestFc is immutable: one instance per combination
            if function in FCB_FUNCTIONS:
                fc = RequestFc(function, self.fcb, self.fcv)
            else:
                fc = RequestFc(function)
            fc = _FC_MEMO.setdefault(key, fc)
        return fc

    def acknowledged(self) -> FcbState:
        return _ACKNOWLEDGED[self.fcb]

    @staticmethod
    def reset() -> FcbState:
        return FcbState()

    @staticmethod
    def unsequenced(function: RequestFunction) -> RequestFc:
        return RequestFc(function)


_FC_MEMO: dict[tuple[RequestFunction, bool, bool], RequestFc] = {}
_ACKNOWLEDGED: Final = {fcb: FcbState(fcb=not fcb, fcv=True) for fcb in (False, True)}
"""The state after an acknowledged SRD (the state is immutable: two instances serve)."""


@dataclass(frozen=True)
class SlaveFcbMemory:
    """Slave-side repeat detection (◐: the fact sheet marks repeated-FCB behaviour unchecked).

    FCV = 0 starts a new sequence; with FCV = 1 an FCB equal to the last one marks a
    retransmission, to be answered with the previous response.
    """

    last_fcb: bool | None = None

    def receive(self, fc: RequestFc) -> tuple[bool, SlaveFcbMemory]:
        """Return ``(is_repeat, new_memory)`` for a request carrying ``fc``."""
        if fc.function not in FCB_FUNCTIONS:
            return False, self
        is_repeat = fc.fcv and self.last_fcb is not None and fc.fcb == self.last_fcb
        return is_repeat, SlaveFcbMemory(fc.fcb)
