"""The contract between the DeviceNet adapter and its device profiles.

One :class:`DnProfile` instance per configured drive, built by the factory its device
names in the device registry (gateway/devices.py, read into :data:`PROFILES`: device ->
"module:Class"), so the adapter never names a device. A profile says:

- how the desired command becomes the output assembly and the input assembly becomes
  drive-state changes (:meth:`DnProfile.outputs`, :meth:`DnProfile.inputs`) and what the
  hub may ask of the drive (:meth:`DnProfile.capabilities`);
- how the drive is set up once the scanner has it online (:meth:`DnProfile.on_connect`:
  check the assemblies in force, read what the gateway needs, write ``startup_params``)
  and what it reads now and then afterwards (:meth:`DnProfile.poll_status`);
- how its parameters and standard objects are reached through explicit messages, with
  the device's own error texts (:meth:`DnProfile.read_param` and the rest);
- what it adds to the offline event, to the fault reset events and to the diagnostics.

The profile reaches its drive through a :class:`DrivePort` the adapter gives it: explicit
requests (through the scanner's job queue), events, and the hub updates that follow a
change of capabilities or of the parameter values it shows.

Optional parts have defaults in :class:`DnProfile` itself: a profile subclasses it and
overrides what its device has. Adding a DeviceNet device is then its own package with
a class implementing this contract, plus its registration in gateway/devices.py.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from adapters.devicenet.codec.datatypes import AttributeValue
from adapters.devicenet.codec.eds import Param
from adapters.devicenet.codec.explicit import ErrorResponse, Request, Response
from adapters.devicenet.scanner.events import IoKind
from gateway.adapter import Capabilities, EventKind, ParamValue
from gateway.devices import devices_of
from gateway.errors import AdapterError, GatewayError, ParameterError
from gateway.loader import load
from gateway.model import DesiredCommand, Device, Readings

if TYPE_CHECKING:
    from gateway.config import DriveConfig
    from gateway.schema import Table

BUS = "devicenet"
"""The adapter name the registry's DeviceNet devices give as their ``bus``."""

PROFILES: dict[Device, str] = {
    d: d.spec.profile for d in Device if d in devices_of(BUS) and d.spec.profile
}
"""Device -> "module:Class" of its :class:`DnProfile` factory (from the registry)."""


class NotConfigured(AdapterError):
    """A drive's configuration at connect failed; the text says why."""


class NodeOptions(Protocol):
    """The DeviceNet node keys of a drive, whatever its device, as the adapter reads them
    from the options its profile parsed: the I/O connection, the identity to check, the
    parameters its EDS names, Automatic Device Replacement."""

    @property
    def connection(self) -> IoKind: ...

    @property
    def ack(self) -> bool: ...

    @property
    def io_sizes(self) -> tuple[int, int]:
        """(produced, consumed) bytes of the I/O connection."""
        ...

    @property
    def check_identity(self) -> bool: ...

    @property
    def vendor_id(self) -> int: ...

    @property
    def product_code(self) -> int | None: ...

    @property
    def product_name(self) -> str | None: ...

    @property
    def product_type(self) -> int | None: ...

    @property
    def revision(self) -> tuple[int, int] | None: ...

    @property
    def params(self) -> Mapping[int, Param]:
        """P number -> the EDS parameter that names it."""
        ...

    @property
    def adr(self) -> bool: ...


class DrivePort(Protocol):
    """What a profile may do with its drive, provided by the adapter."""

    @property
    def bitrate(self) -> int:
        """The line's configured bit rate (bus key ``bitrate``)."""
        ...

    @property
    def io_timeout(self) -> float:
        """How long the drive's I/O connection lasts without the master's data before the
        drive sees it lost (4 x the expected packet rate, fact sheet 2.9)."""
        ...

    async def request(self, body: Request) -> Response:
        """An explicit request to the drive; the reply as it came (an error reply too).

        Raises ``gateway.errors.DriveOffline`` when the drive is not online and
        ``gateway.errors.GatewayTimeout`` when it does not answer in time.
        """
        ...

    def event(self, kind: EventKind, text: str, **data: Any) -> None:
        """An event of the drive (faults, configuration, bus)."""
        ...

    def capabilities_changed(self) -> None:
        """The profile's :meth:`DnProfile.capabilities` changed: give them to the hub."""
        ...

    def values_changed(self) -> None:
        """The profile's :attr:`DnProfile.values` changed: publish them."""
        ...


def reply_data(response: Response) -> bytes:
    """The data of a success reply; an error reply is a ParameterError with its CIP text."""
    if isinstance(response, ErrorResponse):
        raise ParameterError(response.text, code=response.general_status)
    return response.encode_data()


class DnProfile(Protocol):
    """One configured DeviceNet drive's device profile (stateful: one instance per drive).

    The methods with a body are the defaults of the optional parts.
    """

    device: ClassVar[Device]

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> NodeOptions:
        """The drive's keys of the config table: the DeviceNet node keys a device shares
        (:class:`NodeOptions`) and its own."""
        ...

    reset_note: ClassVar[str | None] = None
    """What a fault reset does to the drive's connection, added to the fault reset event
    and to an offline event that follows a reset within :data:`RESET_OFFLINE_WINDOW`;
    None: the drive stays online through a reset."""

    # ---------------------------------------------------------------- I/O

    @property
    def ready(self) -> bool:
        """Whether :meth:`outputs` and :meth:`inputs` can be used (the scale is known)."""
        ...

    def capabilities(self) -> Capabilities | None:
        """Speed scale and the commands the drive refuses (None while the scale is unknown)."""
        ...

    def outputs(self, desired: DesiredCommand, fault_reset: bool) -> bytes:
        """The output assembly for the desired command (the reset bit while ``fault_reset``)."""
        ...

    def inputs(self, data: bytes, desired: DesiredCommand) -> Readings:
        """Drive-state changes (DriveState field names) from the input assembly; the raw
        values it shows go into :attr:`values`. Raises a DeviceNetDecodeError on bad data."""
        ...

    @property
    def values(self) -> dict[str, float | int]:
        """The raw values the drive shows (I/O words and parameters read)."""
        return {}

    # ---------------------------------------------------------------- connection

    async def on_connect(self, port: DrivePort) -> None:
        """Set the drive up once the scanner has it online; until this returns the drive
        gets idle I/O. Raise :class:`NotConfigured` (or let DriveOffline/GatewayTimeout
        through) to leave it not configured: the adapter tries again later."""
        return None

    def configured_text(self) -> str:
        """The event text once :meth:`on_connect` succeeded."""
        return "configured"

    async def poll_status(self, port: DrivePort) -> None:
        """Read the drive's status now and then (every ``status_interval``) once configured."""
        return None

    def offline_note(self) -> str | None:
        """What the drive does on its own when its I/O connection times out (offline event)."""
        return None

    def diagnostics(self) -> dict[str, Any]:
        """The profile's entries of the drive's diagnostics."""
        return {}

    # ---------------------------------------------------------------- explicit access

    async def read_param(self, port: DrivePort, number: int, subindex: int) -> ParamValue:
        """Raise ``gateway.errors.ParameterError`` with the device's own text on refusal."""
        ...

    async def write_param(
        self, port: DrivePort, number: int, subindex: int, value: ParamValue
    ) -> None: ...

    async def read_object(
        self, port: DrivePort, class_id: int, instance_id: int, attribute_id: int
    ) -> AttributeValue:
        """Get_Attribute_Single on a standard object the device's manual lists."""
        raise ParameterError(f"{self.device.value}: no table of standard objects")

    async def write_object(
        self,
        port: DrivePort,
        class_id: int,
        instance_id: int,
        attribute_id: int,
        value: AttributeValue,
    ) -> None:
        """Set_Attribute_Single on a standard object the device's manual lists (never one
        that commands the drive: commands come from the hub, rule 1)."""
        raise ParameterError(f"{self.device.value}: no table of standard objects")


RESET_OFFLINE_WINDOW = 10.0  # s after a fault reset in which going offline is its doing


class ProfileFactory(Protocol):
    """A :class:`DnProfile` class, built from a drive's id and its parsed drive table."""

    device: ClassVar[Device]

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> NodeOptions: ...

    def __call__(self, drive_id: str, options: Any) -> DnProfile:
        """``options``: what this class's :meth:`parse_options` gave."""
        ...


def load_profile(device: Device) -> ProfileFactory:
    """Import the profile class of a device (lazily)."""
    try:
        target = PROFILES[device]
    except KeyError:
        raise GatewayError(f"no DeviceNet profile for {device.value}") from None
    factory: ProfileFactory = load(target)
    return factory
