"""The DeviceNet bus table (read with gateway.schema.Table).

Bus keys: interface, channel, bitrate, mac, vendor_id, poll_interval,
expected_packet_rate, response_timeout, explicit_timeout, explicit_epr, dupmac_timeout,
retry_max, status_interval, simulate. A drive's keys are its device's
(:meth:`~adapters.devicenet.contract.DnProfile.parse_options`; the CFW-08's:
:mod:`adapters.devicenet.cfw08.options`). See docs/devices.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from adapters.devicenet.codec.eds import Eds, decode_eds
from adapters.devicenet.errors import EdsError
from adapters.devicenet.link import REFUSED_INTERFACES
from gateway.schema import Table
from gateway.vendorfile import VendorFileError, read_vendor_file

BITRATES = (125_000, 250_000, 500_000)  # DeviceNet rates (seed table 4, P702)
# The vendor ID the scanner's Duplicate MAC ID check frames carry (fact sheet 2.3). 0 is
# "Reserved"; the gateway has no ODVA-assigned ID, so the default is 0xFFFF, the top of
# the UINT range, far above any ID assigned, and never a real vendor's (docs/devices.md).
SCANNER_VENDOR_ID = 0xFFFF


@dataclass(frozen=True, slots=True)
class BusOptions:
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: int = 125_000
    mac: int = 0
    poll_interval: float = 0.05
    expected_packet_rate: float = 0.2
    response_timeout: float = 0.1
    explicit_timeout: float = 1.0
    dupmac_timeout: float = 1.0
    retry_max: float = 30.0
    status_interval: float = 2.0
    simulate: bool = False
    vendor_id: int = SCANNER_VENDOR_ID
    explicit_epr: float = 2.5  # s, fact sheet 2.9: the usual explicit connection EPR


def parse_bus(t: Table) -> BusOptions:
    d = BusOptions()
    interface = t.string("interface", d.interface)
    if not interface:
        raise t.error("interface", "must name a python-can interface")
    refused = REFUSED_INTERFACES.get(interface)
    if refused is not None:
        raise t.error("interface", refused)
    poll = t.number("poll_interval", d.poll_interval, minimum=0.001, maximum=10.0)
    epr = t.number("expected_packet_rate", d.expected_packet_rate, minimum=0.01, maximum=60.0)
    if epr < poll:
        raise t.error(
            "expected_packet_rate", f"{epr:g} s is shorter than poll_interval ({poll:g} s)"
        )
    explicit_timeout = t.number("explicit_timeout", d.explicit_timeout, minimum=0.01, maximum=30.0)
    # the EPR attribute is 16-bit ms (fact sheet 2.9); a request must fit in a connection's life
    explicit_epr = t.number("explicit_epr", d.explicit_epr, minimum=0.1, maximum=65.535)
    if explicit_epr < explicit_timeout:
        raise t.error(
            "explicit_epr",
            f"{explicit_epr:g} s is shorter than explicit_timeout ({explicit_timeout:g} s)",
        )
    simulate = t.boolean("simulate", d.simulate)
    if simulate and interface != "virtual":
        raise t.error(
            "simulate",
            f"needs interface = 'virtual' (simulated drives run in-process), not {interface!r}",
        )
    return BusOptions(
        interface=interface,
        channel=t.string("channel", d.channel),
        bitrate=t.integer("bitrate", d.bitrate, allowed=BITRATES, what="a DeviceNet rate"),
        mac=t.integer("mac", d.mac, minimum=0, maximum=63),
        vendor_id=t.integer("vendor_id", d.vendor_id, minimum=0, maximum=0xFFFF),
        poll_interval=poll,
        expected_packet_rate=epr,
        response_timeout=t.number(
            "response_timeout", d.response_timeout, minimum=0.001, maximum=10.0
        ),
        explicit_timeout=explicit_timeout,
        explicit_epr=explicit_epr,
        dupmac_timeout=t.number("dupmac_timeout", d.dupmac_timeout, minimum=0.01, maximum=10.0),
        retry_max=t.number("retry_max", d.retry_max, minimum=0.1, maximum=3600.0),
        status_interval=t.number("status_interval", d.status_interval, minimum=0.1, maximum=3600.0),
        simulate=simulate,
    )


def load_eds(path: str | Path) -> Eds:
    """A drive's EDS file read as a vendor file (:mod:`gateway.vendorfile`: a regular file
    of at most 4 MiB, read within a time bound) and parsed; EdsError naming the file and
    the reason otherwise."""
    try:
        raw = read_vendor_file(Path(path), "an EDS file")
    except VendorFileError as exc:
        raise EdsError(exc.file, 0, "", exc.reason) from None
    return decode_eds(raw, str(path))
