"""The contract between the Profibus DP master and the device profiles and device simulators.

Gateway side, one :class:`DpProfile` instance per configured slave: it says how
to set the slave up (ident number, Chk_Cfg bytes, user parameter data), turns
the hub's desired command into the output telegram and the input telegram into
drive-state changes, and does parameter access over DP-V1 through a
:class:`RecordChannel` the master provides.

Simulator side, one :class:`SimDevice` per simulated slave, plugged into the
generic DP slave simulator: it checks the configuration it is given, answers
data exchange, reacts to lost communication (watchdog expiry, Global_Control
Clear) and answers DP-V1 record reads and writes with its manual's errors.

Profiles are found through :data:`PROFILES` (device -> "module:Class", from the device
registry :mod:`gateway.devices`), so the master never imports a profile module eagerly,
and the MCD 600 profile lives in its own package (adapters/mcd600) while running on this
master.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any, ClassVar, Final, Protocol, cast

from gateway.adapter import Capabilities, ParamValue
from gateway.devices import devices_of
from gateway.errors import GatewayError
from gateway.loader import load
from gateway.model import DesiredCommand, Device, Readings

if TYPE_CHECKING:
    from adapters.profibus.codec.dp import GlobalControl
    from gateway.config import DriveConfig
    from gateway.schema import Table
    from gateway.sim import FaultInjector

BUS: Final = "profibus"
"""The adapter name the registry's Profibus devices give as their ``bus``."""

PROFILES: dict[Device, str] = {
    d: d.spec.profile for d in Device if d in devices_of(BUS) and d.spec.profile
}
"""Device -> "module:Class" of its :class:`DpProfile` (from the registry)."""


class RecordAccessError(GatewayError):
    """A DP-V1 read/write answered negatively (the slave's Error_Code_1/2 and its text)."""

    def __init__(self, text: str, code_1: int, code_2: int = 0, error_decode: int = 0x80) -> None:
        self.text = text
        self.code_1 = code_1
        self.code_2 = code_2
        self.error_decode = error_decode
        super().__init__(f"DP-V1 error 0x{code_1:02X}/0x{code_2:02X}: {text}")


@dataclass(frozen=True, slots=True)
class SlaveSetup:
    """What the master sends a slave at start-up (Set_Prm and Chk_Cfg)."""

    ident_number: int
    cfg: bytes  # Chk_Cfg identifier bytes, exactly as on the wire
    user_prm: bytes = b""  # user parameter data after the standard (and DP-V1) bytes
    input_len: int = 0  # bytes of the input telegram (slave -> master)
    output_len: int = 0  # bytes of the output telegram (master -> slave)
    dpv1: bool = True  # DP-V1 enabled in the Set_Prm DP-V1 status bytes
    group: int = 0  # Global_Control group bits
    origin: str = ""  # where cfg/ident/user_prm come from when not built in (GSD file, module)


DP_STATIONS: Final = (0, 125)  # fact sheet 1.2: station addresses must be <= 125
SET_SLAVE_ADD_DEFAULT: Final = 126  # a station waiting for Set_Slave_Add, never in exchange


@dataclass(frozen=True, slots=True)
class AddressRange:
    """The slave addresses a device accepts, as its manual gives them (``source`` cites it).

    A profile declares it as ``addresses``; the adapter refuses a drive configured outside
    it, and outside the DP station addresses a master can exchange data with (1.2: <= 125;
    a manual's 126 is the Set_Slave_Add default address, see docs/devices.md).
    """

    low: int
    high: int
    source: str

    def refusal(self, device: str, address: int) -> str | None:
        """None when ``address`` is usable, else the reason, naming the range and its source
        (the config error's key names the drive: ``drives[<id>].address``)."""
        low, high = max(self.low, DP_STATIONS[0]), min(self.high, DP_STATIONS[1])
        if low <= address <= high:
            return None
        text = f"{address} is outside the {device} range {self.low}-{self.high}"
        if self.low <= address <= self.high:
            text = (
                f"{address} is in the {device} range {self.low}-{self.high} "
                f"but {SET_SLAVE_ADD_DEFAULT} is the Set_Slave_Add default address, never in "
                f"data exchange"
            )
        return f"{text} ({self.source}); use {low}-{high}"


BUILTIN_TELEGRAM: Final = "its built-in telegram"
"""What fixes the telegram of a profile that has no setting for it (``telegram_text``)."""

DEFAULT_ADDRESSES: Final = AddressRange(*DP_STATIONS, "DP station addresses, fact sheet 1.2")
"""For a profile that declares no ``addresses`` of its own (a test device)."""


class DiagKind(StrEnum):
    """What a profile's event is about (the adapter maps it to the hub's event kind)."""

    FAULT = "fault"
    TRIP = "trip"
    ALARM = "alarm"
    PARAMETER = "parameter"
    INFO = "info"
    CONFIG = "config"
    SAFETY = "safety"


@dataclass(frozen=True, slots=True)
class DiagEvent:
    """Something a profile read from the slave's extended diagnosis, worth an event."""

    text: str
    kind: DiagKind = DiagKind.FAULT
    data: Mapping[str, Any] = field(default_factory=dict)


class RecordChannel(Protocol):
    """DP-V1 MSAC_C1 access to one slave, provided by the master.

    Raises :class:`RecordAccessError` for a negative answer and
    ``gateway.errors.GatewayTimeout`` when the slave does not answer in time.
    """

    async def read_record(self, slot: int, index: int, length: int) -> bytes: ...

    async def write_record(self, slot: int, index: int, data: bytes) -> None: ...


class EventSink(Protocol):
    def __call__(self, text: str, kind: DiagKind = DiagKind.INFO, **data: Any) -> None: ...


class DpProfile(Protocol):
    """One configured slave's device profile (stateful: one instance per drive).

    The hooks below ``addresses`` are optional for a device: :class:`DpProfileBase` has
    their defaults, and a profile subclasses it.
    """

    device: ClassVar[Device]
    addresses: ClassVar[AddressRange]
    """The slave addresses the device accepts (its manual); checked at config time."""
    sees_every_diag: ClassVar[bool]
    """True: ``on_ext_diag`` gets every diagnosis read, empty and unchanged ones included
    (the profile keeps its own memory: the MCD 600); False: only a changed, non-empty one."""
    record_error_texts: ClassVar[Mapping[int, str] | None]
    """The device's own texts of DP-V1 Error_Code_1 values, or None (the standard's)."""
    failsafe_needs_watchdog: ClassVar[bool]
    """True: the device sees a lost master only through the DP watchdog, so with the
    watchdog off the adapter publishes ``failsafe`` false (docs/safety.md)."""
    outputs_in_clear: ClassVar[str]
    """What the device does with the outputs while the line is in Clear: "" when a Clear
    is a stop the line may use for any drive (the MCD 600: a quick stop); else why no
    client's stop reaches it then (a WEG drive: outputs not taken, P0313 acts), and a
    bus with ``clear_on_lost_control`` is refused (decision 0091)."""

    @classmethod
    def safety_warnings(cls, drive: DriveConfig, watchdog: float) -> list[str]:
        """``check-config``: what the drive's config alone says of its reaction to a lost
        master, given the slave's DP watchdog (0: off)."""
        ...

    def unconfigured_outputs(self, desired: DesiredCommand, now: float) -> bytes:
        """The telegram before the profile is configured (the first output after any
        (re)connection, and while ``on_connect`` fails): built fresh, a stop."""
        ...

    @property
    def wants_codes(self) -> bool:
        """True when the status shows a fault or alarm whose code the telegram does not
        carry: the adapter then calls :meth:`read_codes` (the WEG drives)."""
        ...

    @property
    def steady(self) -> bool:
        """True while :meth:`outputs` and :meth:`inputs` depend on nothing but the input
        telegram and the desired command (no pulse running, no poll under way): the
        adapter then need not call them for a reply whose inputs did not change
        (the line's fast path, docs/decisions/0096)."""
        ...

    async def read_codes(self, channel: RecordChannel) -> Readings:
        """Fault and alarm codes read over DP-V1 (when :attr:`wants_codes`)."""
        ...

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> Any:
        """Validate the profile's own keys of the drive's config table."""
        ...

    def setup(self) -> SlaveSetup: ...

    def capabilities(self) -> Capabilities:
        """Speed scale (None for a soft starter) and the commands it refuses, with reasons."""
        ...

    async def on_connect(self, channel: RecordChannel, event: EventSink) -> Readings:
        """After the slave reached data exchange: read scales, write ``startup_params``.

        Returns readings (for example ``speed_base``). Raise
        :class:`gateway.errors.GatewayError` to leave the drive "not configured".
        """
        ...

    def outputs(self, desired: DesiredCommand, now: float) -> bytes:
        """The output telegram for this cycle (fault reset as one edge, state machines)."""
        ...

    def inputs(self, data: bytes, now: float) -> Readings:
        """The readings of an input telegram."""
        ...

    def on_ext_diag(self, data: bytes) -> list[DiagEvent]:
        """Events from the device-related extended diagnosis bytes."""
        ...

    def on_comm_lost(self) -> None:
        """Communication was lost: forget edges and state-machine progress."""
        ...

    async def read_param(self, channel: RecordChannel, number: int, subindex: int) -> ParamValue:
        """Raise ``gateway.errors.ParameterError`` with the device's own text on refusal."""
        ...

    async def write_param(
        self, channel: RecordChannel, number: int, subindex: int, value: ParamValue
    ) -> None: ...


class DpProfileBase:
    """The defaults of :class:`DpProfile`'s optional hooks; a profile subclasses it and
    overrides what its device needs."""

    addresses: ClassVar[AddressRange] = DEFAULT_ADDRESSES
    sees_every_diag: ClassVar[bool] = False
    record_error_texts: ClassVar[Mapping[int, str] | None] = None
    failsafe_needs_watchdog: ClassVar[bool] = False
    outputs_in_clear: ClassVar[str] = ""

    @classmethod
    def safety_warnings(cls, drive: DriveConfig, watchdog: float) -> list[str]:
        return []

    def unconfigured_outputs(self, desired: DesiredCommand, now: float) -> bytes:
        profile = cast("DpProfile", self)
        return profile.outputs(desired, now)

    @property
    def wants_codes(self) -> bool:
        return False

    @property
    def steady(self) -> bool:
        return False  # a profile that does not say otherwise sees every reply

    async def read_codes(self, channel: RecordChannel) -> Readings:
        return {}

    @classmethod
    def telegram_keys(cls, input_bytes: int, output_bytes: int) -> tuple[str, ...]:
        return ()

    @classmethod
    def telegram_text(cls, options: Any) -> str:
        return BUILTIN_TELEGRAM


class ProfileFactory(Protocol):
    device: ClassVar[Device]
    addresses: ClassVar[AddressRange]
    outputs_in_clear: ClassVar[str]

    @classmethod
    def telegram_keys(cls, input_bytes: int, output_bytes: int) -> tuple[str, ...]:
        """The config lines (``key = value``) that give a drive of this device a telegram of
        these sizes, for the stanzas ``drive-gateway profibus scan --toml`` prints (empty:
        none needed, or none gives it)."""
        ...

    @classmethod
    def telegram_text(cls, options: Any) -> str:
        """The setting of the profile's ``options`` that fixes its telegram, as an operator
        knows it (for the error when a GSD module or ``cfg`` gives other sizes)."""
        ...

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> Any: ...

    @classmethod
    def safety_warnings(cls, drive: DriveConfig, watchdog: float) -> list[str]: ...

    def __call__(self, drive: DriveConfig) -> DpProfile: ...


def load_profile(device: Device) -> ProfileFactory:
    """Import the profile class of a device (lazily)."""
    try:
        target = PROFILES[device]
    except KeyError:
        raise GatewayError(f"no Profibus profile for {device.value}") from None
    factory: ProfileFactory = load(target)
    return factory


class SimDevice(Protocol):
    """A simulated device behind the generic DP slave simulator (sans-IO, clock injected).

    The hooks from ``dpv1`` to ``global_control`` are optional for a device:
    :class:`SimDeviceBase` has their defaults, and a simulator subclasses it.
    """

    ident_number: int

    @property
    def dpv1(self) -> bool:
        """Set_Prm carries the DP-V1 status bytes (the user data after them)."""
        ...

    @property
    def reads_user_prm(self) -> bool:
        """Behind a GSD file the device still gets the Set_Prm user data (the MCD 600's
        timeout byte); False: the GSD's checks take it and the device gets none."""
        ...

    @property
    def faults(self) -> FaultInjector | None:
        """The device's own fault injector, shared with the slave (lost replies, noise)."""
        ...

    @property
    def handles_clear(self) -> bool:
        """Global_Control Clear goes to :meth:`clear_mode` (a WEG drive's A138/F238);
        False: a Clear is a lost communication (``comm_lost``)."""
        ...

    def alerts(self, ext: bytes) -> bool:
        """Whether the extended diagnosis ``ext`` is worth a high-priority answer (DH)."""
        ...

    def check_cfg(self, cfg: bytes) -> bool:
        """Chk_Cfg: whether ``cfg`` is accepted (a WEG drive shows P0740 = 3 on a bad one)."""
        ...

    def clear_mode(self, now: float, active: bool) -> None:
        """Global_Control Clear (``active``) or Operate again (when :attr:`handles_clear`)."""
        ...

    def global_control(self, control: GlobalControl, now: float) -> None:
        """Every Global_Control for the slave (Clear, Sync, Freeze: the MCD 600, WEG)."""
        ...

    def baud_detected(self, baudrate: int) -> None:
        """The slave took the line's baud rate (bit/s) at a Set_Prm (a WEG drive shows it
        in P0963 / P754)."""
        ...

    def write_answer_length(self, written: int) -> int:
        """The length a positive DS_Write answer carries for ``written`` bytes (the
        written length by default; a WEG drive answers 0)."""
        ...

    def expected_cfg(self) -> bytes:
        """The Chk_Cfg bytes it accepts (Get_Cfg answers them); others are a Cfg_Fault."""
        ...

    def set_prm(self, user_prm: bytes) -> bool:
        """Take the user parameter data; False is a Prm_Fault."""
        ...

    def exchange(self, outputs: bytes, now: float) -> bytes:
        """One data exchange: take the outputs, return the inputs."""
        ...

    def comm_lost(self, now: float) -> None:
        """The DP watchdog expired or the master sent Global_Control Clear."""
        ...

    def read_record(self, slot: int, index: int, length: int, now: float) -> bytes:
        """DP-V1 read; raise :class:`RecordAccessError` for the manual's negative answers."""
        ...

    def write_record(self, slot: int, index: int, data: bytes, now: float) -> None: ...

    def ext_diag(self) -> bytes:
        """Device-related extended diagnosis bytes (empty when none)."""
        ...

    def tick(self, now: float) -> None:
        """Advance the device's physics to ``now``."""
        ...

    def power_cycle(self, now: float) -> None:
        """Lose power and come back: parameters kept, running state and comm lost."""
        ...


class SimFactory(Protocol):
    """How a device's simulator is built: the class the registry names as its ``simulator``
    (:mod:`gateway.devices`) has this one class method."""

    def for_drive(self, drive: DriveConfig | None) -> SimDevice:
        """The simulated device a configured drive describes (``simulate = true``: its
        profile options, its address), or a default one for ``None``."""
        ...


class SimDeviceBase:
    """The defaults of :class:`SimDevice`'s optional hooks; a simulator subclasses it and
    overrides what its device does."""

    dpv1: bool = True
    reads_user_prm: bool = False
    faults: FaultInjector | None = None
    handles_clear: bool = False

    def expected_cfg(self) -> bytes:
        raise NotImplementedError

    def alerts(self, ext: bytes) -> bool:
        return bool(ext)

    def check_cfg(self, cfg: bytes) -> bool:
        return cfg == self.expected_cfg()

    def clear_mode(self, now: float, active: bool) -> None:
        return None

    def global_control(self, control: GlobalControl, now: float) -> None:
        return None

    def baud_detected(self, baudrate: int) -> None:
        return None

    def write_answer_length(self, written: int) -> int:
        return written
