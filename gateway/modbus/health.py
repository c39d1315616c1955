"""The gateway unit's map: unit 0 and ``modbus.gateway_unit`` report the gateway's health.

Input registers (function 4), mirrored read-only at holding ``MIRROR_OFFSET + n``
(function 3). Nothing of the gateway unit is writable.
"""

from __future__ import annotations

from dataclasses import dataclass

from gateway.modbus.regs import CODE16, COUNTER32, Field, encode_block


@dataclass(frozen=True, slots=True)
class GatewayView:
    """A snapshot of the gateway's health, for the gateway unit's input registers."""

    version: tuple[int, int, int]
    uptime_s: float
    drives: int
    online: int
    modbus_drives: int
    read_only: bool
    connections_open: int
    connections_accepted: int
    connections_refused: int
    requests: int
    exceptions: int
    commands_accepted: int
    commands_refused: int
    bad_frames: int
    adapter_restarts: int
    frame_timeouts: int
    connections_over_limit: int
    connections_over_peer_limit: int
    accept_failures: int


def parse_version(text: str) -> tuple[int, int, int]:
    """``"1.2.3"`` -> (1, 2, 3); missing or non-numeric parts are 0."""
    parts: list[int] = []
    for piece in text.split(".")[:3]:
        digits = ""
        for ch in piece:
            if not ch.isdigit():
                break
            digits += ch
        parts.append(int(digits) if digits else 0)
    while len(parts) < 3:
        parts.append(0)
    return parts[0], parts[1], parts[2]


GATEWAY_INPUTS: tuple[Field[GatewayView], ...] = (
    Field(0, "version_major", CODE16, "", "drive-gateway version, major", lambda g: g.version[0]),
    Field(1, "version_minor", CODE16, "", "version, minor", lambda g: g.version[1]),
    Field(2, "version_patch", CODE16, "", "version, patch", lambda g: g.version[2]),
    Field(3, "uptime_s", COUNTER32, "s", "seconds since the gateway started", lambda g: g.uptime_s),
    Field(5, "drives", CODE16, "count", "drives configured", lambda g: g.drives),
    Field(
        6, "drives_online", CODE16, "count", "drives whose comm state is online", lambda g: g.online
    ),
    Field(
        7,
        "modbus_drives",
        CODE16,
        "count",
        "drives that have a Modbus unit id",
        lambda g: g.modbus_drives,
    ),
    Field(
        8,
        "read_only",
        CODE16,
        "0/1",
        "1: `modbus.read_only` is set (every write refused)",
        lambda g: int(g.read_only),
    ),
    Field(
        9,
        "connections_open",
        CODE16,
        "count",
        "Modbus TCP connections open now",
        lambda g: g.connections_open,
    ),
    Field(
        10,
        "connections_accepted",
        COUNTER32,
        "count",
        "connections accepted since start",
        lambda g: g.connections_accepted,
    ),
    Field(
        12,
        "connections_refused",
        COUNTER32,
        "count",
        "connections refused by `modbus.allow`",
        lambda g: g.connections_refused,
    ),
    Field(
        14, "requests", COUNTER32, "count", "requests received (every unit)", lambda g: g.requests
    ),
    Field(16, "exceptions", COUNTER32, "count", "exception responses sent", lambda g: g.exceptions),
    Field(
        18,
        "commands_accepted",
        COUNTER32,
        "count",
        "writes to drive command registers accepted by the hub",
        lambda g: g.commands_accepted,
    ),
    Field(
        20,
        "commands_refused",
        COUNTER32,
        "count",
        "writes to drive command registers the hub refused (exception 4)",
        lambda g: g.commands_refused,
    ),
    Field(
        22,
        "bad_frames",
        COUNTER32,
        "count",
        "frames with a bad MBAP header or not finished within `modbus.frame_timeout`"
        " (the connection is closed)",
        lambda g: g.bad_frames,
    ),
    Field(
        24,
        "adapter_restarts",
        CODE16,
        "count",
        "fieldbus adapter restarts after a crash, all buses",
        lambda g: g.adapter_restarts,
    ),
    Field(
        25,
        "frame_timeouts",
        COUNTER32,
        "count",
        "of `bad_frames`: a frame begun and not finished within `modbus.frame_timeout`",
        lambda g: g.frame_timeouts,
    ),
    Field(
        27,
        "connections_over_limit",
        COUNTER32,
        "count",
        "connections closed at accept because a connection limit was reached"
        " (`modbus.max_connections` or `modbus.max_connections_per_peer`)",
        lambda g: g.connections_over_limit,
    ),
    Field(
        29,
        "connections_over_peer_limit",
        COUNTER32,
        "count",
        "of `connections_over_limit`: the client's address had"
        " `modbus.max_connections_per_peer` open",
        lambda g: g.connections_over_peer_limit,
    ),
    Field(
        31,
        "accept_failures",
        COUNTER32,
        "count",
        "accepts that failed: no file descriptor (or memory) left; open connections are"
        " still served",
        lambda g: g.accept_failures,
    ),
)
"""Input registers of the gateway unit, mirrored at holding ``MIRROR_OFFSET + n``."""


def encode_gateway_inputs(view: GatewayView) -> list[int]:
    return encode_block(GATEWAY_INPUTS, view)
