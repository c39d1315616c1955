"""CANopen code tables: SDO abort codes, EMCY codes by exact entry then class."""

from __future__ import annotations

from adapters.canopen.codec import codes


def test_abort_texts() -> None:
    assert codes.abort_text(0x06090030) == "value range of parameter exceeded"
    assert codes.abort_message(0x06090030) == "0x06090030 value range of parameter exceeded"
    assert codes.abort_text(0x06020000) == "object does not exist in the object dictionary"
    assert codes.abort_text(0x12345678) == "unknown abort code"


def test_emcy_exact_then_class() -> None:
    assert codes.emcy_text(0x2310) == "continuous over current"
    assert codes.emcy_text(0x3210) == "DC link over-voltage"
    assert codes.emcy_text(0x3220) == "DC link under-voltage"
    assert codes.emcy_text(0x4310) == "excess temperature drive"
    assert codes.emcy_text(0x5113) == "U3 = supply +5 V"
    assert codes.emcy_text(0x7121) == "motor blocked"
    assert codes.emcy_text(0x8130) == "life guard error or heartbeat error"
    assert codes.emcy_text(0x8611) == "following error"
    assert codes.emcy_text(0xFF42) == "device specific"
    assert codes.emcy_text(0x2315) == "continuous over current"  # by its 0xXXX0 class
    assert codes.emcy_text(0x3399) == "output voltage"  # by its 0xXX00 class
    assert codes.emcy_text(0x9ABC) == "external error"  # by its 0xX000 class
    assert codes.emcy_text(0x0000) == "error reset or no error"
    assert codes.emcy_text(0x0042) == "unknown error code"


def test_error_register() -> None:
    assert codes.error_register_texts(0x03) == ("generic error", "current")
    assert codes.error_register_texts(0) == ()
