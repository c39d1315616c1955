"""The Profibus line's serial port: the shared serial link (:mod:`adapters.link.serial`) with
the Profibus character format, 8E1 (fact sheet 1.1: 11-bit characters, even parity)."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, Final

import serial

from adapters.link.portlock import PortHeld
from adapters.link.serial import (
    OPEN_ERRORS,
    URL_SCHEMES,
    CharFormat,
    Rs485,
    SerialLink,
    SerialLinks,
    SerialPort,
    in_thread,
    is_pty,
    is_url,
    set_rs485,
)
from adapters.link.serial import open_link as open_serial_link
from adapters.link.serial import open_port as open_serial_port

__all__ = [
    "OPEN_ERRORS",
    "PROFIBUS_CHARS",
    "URL_SCHEMES",
    "PortHeld",
    "Rs485",
    "SerialLink",
    "SerialLinks",
    "in_thread",
    "is_pty",
    "is_url",
    "open_link",
    "open_port",
    "profibus_port",
    "set_rs485",
]

PROFIBUS_CHARS: Final = CharFormat(serial.EIGHTBITS, serial.PARITY_EVEN, serial.STOPBITS_ONE)
"""Fact sheet 1.1: 8 data bits, even parity, 1 stop bit."""


def open_port(port: str, baudrate: int, rs485: Rs485 = Rs485.AUTO) -> Any:
    """An open port set to 8E1 at ``baudrate`` (:func:`adapters.link.serial.open_port`)."""
    return open_serial_port(port, baudrate, PROFIBUS_CHARS, rs485)


async def open_link(
    port: str,
    baudrate: int,
    loop: asyncio.AbstractEventLoop,
    on_data: Callable[[bytes, float], None],
    on_error: Callable[[BaseException], None],
    *,
    rs485: Rs485 = Rs485.AUTO,
) -> SerialLink:
    """Open ``port`` at 8E1 without blocking the loop (:func:`adapters.link.serial.open_link`)."""
    return await open_serial_link(
        port, baudrate, loop, on_data, on_error, char=PROFIBUS_CHARS, rs485=rs485
    )


def profibus_port(port: str, baudrate: int, rs485: Rs485 = Rs485.AUTO) -> SerialPort:
    """The real line's link factory: ``port`` at 8E1."""
    return SerialPort(port, baudrate, PROFIBUS_CHARS, rs485)
