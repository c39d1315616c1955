"""Slave_Diag reply: the six standard bytes and the extended diagnosis blocks.

Sans-IO codec written from the fact sheet (``reference/protocol-facts.md``) 1.8: Status_1..3
with every flag named, Master_Add, Ident_Number; device-, identifier- and channel-related
blocks; DP-V1 alarm and status inside a device-related block (when the slave runs DP-V1).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Final, Self

from adapters.profibus.codec.fdl import MAX_DU
from adapters.profibus.codec.pdu import bit, bits, fail, need
from adapters.profibus.errors import DecodeFailure, require_length, whole_raw
from gateway.errors import FrameEncodeError, require_int

NO_MASTER: Final = 0xFF  # 1.8: Master_Add 0xFF = no master


class ChannelDirection(IntEnum):
    """Channel-related diagnosis byte 2 bits 7-6 (fact sheet 1.8)."""

    RESERVED = 0b00
    INPUT = 0b01
    OUTPUT = 0b10
    INPUT_OUTPUT = 0b11


class ChannelType(IntEnum):
    """Channel-related diagnosis byte 3 bits 7-5 (fact sheet 1.8)."""

    RESERVED = 0
    BIT = 1
    BIT2 = 2
    BIT4 = 3
    BYTE = 4
    WORD = 5
    DWORD = 6
    RESERVED_7 = 7


CHANNEL_ERROR_TEXTS: Final[dict[int, str]] = {  # 1.8: byte 3 bits 4-0; 16-31 vendor
    1: "short circuit",
    2: "undervoltage",
    3: "overvoltage",
    4: "overload",
    5: "overtemperature",
    6: "wire break",
    7: "upper limit exceeded",
    8: "lower limit exceeded",
    9: "error",
}


def channel_error_text(code: int) -> str:
    if code in CHANNEL_ERROR_TEXTS:
        return CHANNEL_ERROR_TEXTS[code]
    return "vendor specific" if 16 <= code <= 31 else "reserved"


class AlarmType(IntEnum):
    """DP-V1 alarm types, type byte b7 = 0 (fact sheet 1.8)."""

    DIAGNOSTIC = 1
    PROCESS = 2
    PULL = 3
    PLUG = 4
    STATUS = 5
    UPDATE = 6


class StatusType(IntEnum):
    """DP-V1 status types, type byte b7 = 1 (fact sheet 1.8)."""

    STATUS = 1
    MODULE_STATUS = 2


class AlarmSpecifier(IntEnum):
    """Specifier bits 1-0 (fact sheet 1.8)."""

    NONE = 0
    APPEARS = 1
    DISAPPEARS = 2
    DISAPPEARS_OTHERS_REMAIN = 3


_BLOCK_DEVICE: Final = 0b00
_BLOCK_IDENTIFIER: Final = 0b01
_BLOCK_CHANNEL: Final = 0b10
_MAX_BLOCK: Final = 63  # header bits 5-0: block length including the header


@dataclass(frozen=True)
class DeviceDiag:
    """Device-related block (header 00xxxxxx): manufacturer data, up to 62 bytes."""

    data: bytes

    def encode(self) -> bytes:
        data = require_length("device diagnosis", self.data, 0, _MAX_BLOCK - 1)
        return bytes((len(data) + 1,)) + data


@dataclass(frozen=True)
class IdentifierDiag:
    """Identifier-related block (header 01xxxxxx): bit n set = module n has a fault."""

    bitmap: bytes

    @property
    def faulty_modules(self) -> tuple[int, ...]:
        return tuple(
            i * 8 + n for i, byte in enumerate(self.bitmap) for n in range(8) if bit(byte, n)
        )

    @classmethod
    def for_modules(cls, modules: Iterable[int], size: int | None = None) -> Self:
        """Bitmap with the given module numbers set, ``size`` bytes (default: just enough)."""
        mods = sorted(set(modules))
        if mods and mods[0] < 0:
            raise FrameEncodeError("module numbers start at 0")
        length = size if size is not None else (mods[-1] // 8 + 1 if mods else 1)
        bitmap = bytearray(length)
        for m in mods:
            if m >= 8 * length:
                raise FrameEncodeError(f"module {m} does not fit a {length}-byte bitmap")
            bitmap[m // 8] |= 1 << (m % 8)
        return cls(bytes(bitmap))

    def encode(self) -> bytes:
        data = require_length("identifier diagnosis", self.bitmap, 0, _MAX_BLOCK - 1)
        return bytes((_BLOCK_IDENTIFIER << 6 | (len(data) + 1),)) + data


@dataclass(frozen=True)
class ChannelDiag:
    """Channel-related block, always 3 bytes (fact sheet 1.8)."""

    module: int  # header bits 5-0
    channel: int  # byte 2 bits 5-0
    direction: ChannelDirection
    channel_type: ChannelType
    error: int  # byte 3 bits 4-0, see CHANNEL_ERROR_TEXTS

    @property
    def error_text(self) -> str:
        return channel_error_text(self.error)

    def encode(self) -> bytes:
        return bytes(
            (
                _BLOCK_CHANNEL << 6 | require_int("module", self.module, 0, 63),
                ChannelDirection(self.direction) << 6 | require_int("channel", self.channel, 0, 63),
                ChannelType(self.channel_type) << 5 | require_int("error", self.error, 0, 31),
            )
        )


@dataclass(frozen=True)
class AlarmDiag:
    """DP-V1 alarm inside a device-related block (fact sheet 1.8, type byte b7 = 0)."""

    alarm_type: int  # see AlarmType, 1..127
    slot: int
    specifier: AlarmSpecifier = AlarmSpecifier.APPEARS
    add_ack: bool = False
    sequence: int = 0  # 0..31
    data: bytes = b""

    def encode(self) -> bytes:
        data = require_length("alarm data", self.data, 0, _MAX_BLOCK - 4)
        return (
            bytes(
                (
                    len(data) + 4,
                    require_int("alarm_type", self.alarm_type, 0, 127),
                    require_int("slot", self.slot, 0, 255),
                    _specifier_byte(self.specifier, self.add_ack, self.sequence),
                )
            )
            + data
        )


@dataclass(frozen=True)
class StatusDiag:
    """DP-V1 status inside a device-related block (fact sheet 1.8, type byte b7 = 1)."""

    status_type: int  # see StatusType, 0..127
    slot: int
    specifier: AlarmSpecifier = AlarmSpecifier.NONE
    data: bytes = b""

    def encode(self) -> bytes:
        data = require_length("status data", self.data, 0, _MAX_BLOCK - 4)
        return (
            bytes(
                (
                    len(data) + 4,
                    0x80 | require_int("status_type", self.status_type, 0, 127),
                    require_int("slot", self.slot, 0, 255),
                    AlarmSpecifier(self.specifier),
                )
            )
            + data
        )


def _specifier_byte(specifier: AlarmSpecifier, add_ack: bool, sequence: int) -> int:
    """1.8: b1-0 specifier, b2 Add_Ack, b7-3 sequence number."""
    return (
        require_int("sequence", sequence, 0, 31) << 3
        | (0x04 if add_ack else 0)
        | AlarmSpecifier(specifier)
    )


def decode_specifier(value: int) -> tuple[AlarmSpecifier, bool, int]:
    """Split a specifier byte into (specifier, add_ack, sequence) (fact sheet 1.8)."""
    return AlarmSpecifier(value & 0x03), bit(value, 2), value >> 3


DiagBlock = DeviceDiag | IdentifierDiag | ChannelDiag | AlarmDiag | StatusDiag


def _device_text(block: DeviceDiag) -> str:
    return f"device diagnosis {block.data.hex(' ').upper() or '(empty)'}"


def _identifier_text(block: IdentifierDiag) -> str:
    modules = block.faulty_modules
    if not modules:
        return "no module reports a fault"
    return f"module(s) {', '.join(map(str, modules))} report a fault"


def _channel_text(block: ChannelDiag) -> str:
    direction = ChannelDirection(block.direction).name.lower().replace("_", "/")
    kind = ChannelType(block.channel_type).name.lower()
    return (
        f"module {block.module} channel {block.channel} ({direction}, {kind}): "
        f"{block.error_text} (error {block.error})"
    )


def _kind_name(value: int, kind: type[IntEnum]) -> str:
    try:
        return kind(value).name.lower().replace("_", " ")
    except ValueError:
        return f"type {value}"


def _alarm_text(block: AlarmDiag) -> str:
    what = AlarmSpecifier(block.specifier).name.lower().replace("_", " ")
    data = f" {block.data.hex(' ').upper()}" if block.data else ""
    return f"{_kind_name(block.alarm_type, AlarmType)} alarm, slot {block.slot}, {what}{data}"


def _status_text(block: StatusDiag) -> str:
    data = f" {block.data.hex(' ').upper()}" if block.data else ""
    return f"{_kind_name(block.status_type, StatusType)} message, slot {block.slot}{data}"


_BLOCK_TEXTS: Final[dict[type, Callable[[Any], str]]] = {
    DeviceDiag: _device_text,
    IdentifierDiag: _identifier_text,
    ChannelDiag: _channel_text,
    AlarmDiag: _alarm_text,
    StatusDiag: _status_text,
}


def describe_blocks(blocks: Iterable[DiagBlock]) -> str:
    """The extended diagnosis in words, block by block (fact sheet 1.8 field names)."""
    return "; ".join(_BLOCK_TEXTS[type(b)](b) for b in blocks)


def _decode_device_block(block: bytes, dpv1: bool) -> DiagBlock:
    body = block[1:]
    if not dpv1 or len(body) < 3:
        return DeviceDiag(body)
    kind, slot, spec = body[0], body[1], body[2]
    specifier, add_ack, sequence = decode_specifier(spec)
    if kind & 0x80:
        return StatusDiag(kind & 0x7F, slot, specifier, body[3:])
    return AlarmDiag(kind, slot, specifier, add_ack, sequence, body[3:])


def decode_diag_blocks(data: bytes, *, dpv1: bool = False) -> tuple[DiagBlock, ...]:
    """Decode the extended diagnosis after the six standard bytes (fact sheet 1.8).

    With ``dpv1`` a device-related block of 4+ bytes is read as a DP-V1 alarm or status.
    """
    data = bytes(data)
    blocks: list[DiagBlock] = []
    pos = 0
    while pos < len(data):
        head = data[pos]
        kind = head >> 6
        if kind == _BLOCK_CHANNEL:
            if pos + 3 > len(data):
                raise fail(DecodeFailure.TRUNCATED, "channel diagnosis needs 3 bytes", data)
            b2, b3 = data[pos + 1], data[pos + 2]
            blocks.append(
                ChannelDiag(
                    head & 0x3F,
                    b2 & 0x3F,
                    ChannelDirection(b2 >> 6),
                    ChannelType(b3 >> 5),
                    b3 & 0x1F,
                )
            )
            pos += 3
            continue
        size = head & 0x3F
        if kind not in (_BLOCK_DEVICE, _BLOCK_IDENTIFIER):
            raise fail(DecodeFailure.UNSUPPORTED, f"diagnosis block header 0x{head:02X}", data)
        if size == 0 or pos + size > len(data):
            raise fail(DecodeFailure.BAD_LENGTH, f"diagnosis block length {size}", data)
        block = data[pos : pos + size]
        if kind == _BLOCK_DEVICE:
            blocks.append(_decode_device_block(block, dpv1))
        else:
            blocks.append(IdentifierDiag(block[1:]))
        pos += size
    return tuple(blocks)


@dataclass(frozen=True)
class SlaveDiag:
    """Slave_Diag reply, slave SAP 60 -> master SAP 62 (fact sheet 1.8).

    Flags marked (master) are set by the master itself, never by a slave.
    Reserved bits (Status_2 b6, Status_3 b0-6) are ignored.
    """

    ident_number: int
    # Status_1 (byte 0)
    station_not_existent: bool = False  # b0 (master)
    station_not_ready: bool = False  # b1
    cfg_fault: bool = False  # b2
    ext_diag: bool = False  # b3
    not_supported: bool = False  # b4
    invalid_slave_response: bool = False  # b5 (master)
    prm_fault: bool = False  # b6
    master_lock: bool = False  # b7 (master)
    # Status_2 (byte 1)
    prm_req: bool = False  # b0
    stat_diag: bool = False  # b1: keep reading diagnosis
    always_one: bool = True  # b2, always 1
    wd_on: bool = False  # b3
    freeze_mode: bool = False  # b4
    sync_mode: bool = False  # b5
    deactivated: bool = False  # b7 (master)
    # Status_3 (byte 2)
    ext_diag_overflow: bool = False  # b7
    master_address: int = NO_MASTER  # byte 3
    blocks: tuple[DiagBlock, ...] = ()

    @property
    def ready_for_data_exchange(self) -> bool:
        """Fact sheet 1.5 step 5: Not_Ready, Cfg_Fault, Prm_Fault and Prm_Req all 0."""
        return not (self.station_not_ready or self.cfg_fault or self.prm_fault or self.prm_req)

    def encode(self) -> bytes:
        require_int("ident_number", self.ident_number, 0, 0xFFFF)
        head = bytes(
            (
                bits(
                    (self.station_not_existent, 0),
                    (self.station_not_ready, 1),
                    (self.cfg_fault, 2),
                    (self.ext_diag, 3),
                    (self.not_supported, 4),
                    (self.invalid_slave_response, 5),
                    (self.prm_fault, 6),
                    (self.master_lock, 7),
                ),
                bits(
                    (self.prm_req, 0),
                    (self.stat_diag, 1),
                    (self.always_one, 2),
                    (self.wd_on, 3),
                    (self.freeze_mode, 4),
                    (self.sync_mode, 5),
                    (self.deactivated, 7),
                ),
                bits((self.ext_diag_overflow, 7)),
                require_int("master_address", self.master_address, 0, 255),
                self.ident_number >> 8,
                self.ident_number & 0xFF,
            )
        )
        blocks = b"".join(_encode_block(b) for b in self.blocks)
        return head + require_length("extended diagnosis", blocks, 0, MAX_DU - 6)

    @classmethod
    def decode(cls, data: bytes, *, dpv1: bool = False) -> Self:
        data = bytes(data)
        need(data, 6, "Slave_Diag")
        s1, s2, s3 = data[0], data[1], data[2]
        with whole_raw(data):
            blocks = decode_diag_blocks(data[6:], dpv1=dpv1)
        return cls(
            ident_number=data[4] << 8 | data[5],
            station_not_existent=bit(s1, 0),
            station_not_ready=bit(s1, 1),
            cfg_fault=bit(s1, 2),
            ext_diag=bit(s1, 3),
            not_supported=bit(s1, 4),
            invalid_slave_response=bit(s1, 5),
            prm_fault=bit(s1, 6),
            master_lock=bit(s1, 7),
            prm_req=bit(s2, 0),
            stat_diag=bit(s2, 1),
            always_one=bit(s2, 2),
            wd_on=bit(s2, 3),
            freeze_mode=bit(s2, 4),
            sync_mode=bit(s2, 5),
            deactivated=bit(s2, 7),
            ext_diag_overflow=bit(s3, 7),
            master_address=data[3],
            blocks=blocks,
        )


def _encode_block(block: DiagBlock) -> bytes:
    if not isinstance(block, DeviceDiag | IdentifierDiag | ChannelDiag | AlarmDiag | StatusDiag):
        raise FrameEncodeError(f"not a diagnosis block: {block!r}")
    return block.encode()
