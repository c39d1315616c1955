"""The WEG CFW-08's DeviceNet profile: what the adapter asks of one CFW-08 drive.

Once the scanner has the drive online (allocated, identity and sizes checked, EPR
set), :meth:`Cfw08Profile.on_connect` configures it through explicit messages: the I/O
connection's paths must name the configured assembly pair (seed tables 13-14; P710
counts only after a reset, seed 4.1.8), P313 is read (the drive's own reaction to a
communication error, seed 4.1.3), the maximum speed is read if the config asks, and
``startup_params`` are written and read back; P702 is checked against the line's rate
(seed 4.1.6) and P070 read (seed 4.1.1). Until that succeeds the adapter sends idle
(zero-length) I/O and the drive stays ``connecting``: it never runs half-set.

What the drive does without the gateway and whether it obeys it are published with the
readings (issue 32 items 5, 6): ``failsafe`` from P313 (seed 4.1.3), ``local_control``
from Ctrl from Net (21/71, seed 3.1.1), from the situation bit of 150 with the command
source of that situation (P229/P230, seed 4.2.4-4.2.5), or on 20/70 (no such bit) from
Control Supervisor attribute 15 (table 16), read at connect and every status poll; the
other sources (P220-P231) every fifth status poll, and at the next one after the I/O shows
the drive's situation changing (docs/decisions/0106).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

from adapters.devicenet.cfw08.assemblies import (
    P070_COMM_ERROR,
    P070_TEXT,
    P081_IDLE,
    P081_TEXT,
    P313_TEXT,
    SPEED_REF_MAX_RPM,
    AssemblyPair,
    AttributePath,
    ProfileSettings,
    capabilities,
    command_assembly,
    decode_parameter,
    encode_parameter,
    failsafe_of,
    fault_text,
    parameter_path,
    state_changes,
    value_text,
)
from adapters.devicenet.cfw08.objects import (
    P070,
    P081,
    P313,
    P702,
    P702_BAUD,
    P710,
    SEED_PARAMETERS,
    STANDARD_OBJECTS,
    AttributeSpec,
    decode_attribute,
    encode_attribute,
)
from adapters.devicenet.cfw08.options import DriveOptions, parse_drive
from adapters.devicenet.codec import objects
from adapters.devicenet.codec.cip import CipClass
from adapters.devicenet.codec.datatypes import AttributeValue
from adapters.devicenet.codec.explicit import GetAttributeSingle, SetAttributeSingle
from adapters.devicenet.contract import DnProfile, DrivePort, NotConfigured, reply_data
from adapters.devicenet.errors import DeviceNetDecodeError
from adapters.devicenet.scanner.events import IoKind
from gateway.adapter import (
    Capabilities,
    EventKind,
    ParamInfo,
    ParamTable,
    ParamValue,
    param_table,
)
from gateway.config import DriveConfig
from gateway.errors import FrameEncodeError, ParameterError
from gateway.model import DesiredCommand, Device, Readings
from gateway.schema import Table


@dataclass(slots=True)
class Cfw08Profile(DnProfile):
    """One CFW-08 drive (seed ``weg-cfw08-devicenet.pt.md``)."""

    device: ClassVar[Device] = Device.CFW08
    reset_note: ClassVar[str | None] = "the drive goes offline during a reset, seed 3.4"

    drive_id: str
    opts: DriveOptions
    settings: ProfileSettings | None = None
    p313: int | None = None
    io_timeout: float | None = None  # s without I/O before the drive sees a lost master
    ctrl_from_net: bool | None = None  # Control Supervisor attribute 15 (20/70 only)
    in_force: str | None = None  # the assembly pair the I/O connection's paths name
    io_values: dict[str, float | int] = field(default_factory=dict)
    params: dict[str, int] = field(default_factory=dict)
    status_polls: int = 0  # since the last read of every source (SOURCES_EVERY)
    sources_due: bool = False  # the I/O's situation changed: every source at the next poll
    situation: tuple[object, object] | None = None  # remote and reference bits last seen

    @classmethod
    def parse_options(cls, table: Table, drive: DriveConfig) -> DriveOptions:
        return parse_drive(table, drive)

    def __post_init__(self) -> None:
        if self.opts.max_rpm is not None:
            self.settings = _settings(self.opts, self.opts.max_rpm)

    # ---------------------------------------------------------------- I/O

    @property
    def ready(self) -> bool:
        return self.settings is not None

    def capabilities(self) -> Capabilities | None:
        """The assemblies' capabilities with the seed's parameter table (the adapter puts
        the drive's EDS table in its place when it has one)."""
        if self.settings is None:
            return None
        return replace(capabilities(self.settings), params=seed_param_table())

    def outputs(self, desired: DesiredCommand, fault_reset: bool) -> bytes:
        return command_assembly(self._scale(), desired, fault_reset).encode()

    def inputs(self, data: bytes, desired: DesiredCommand) -> Readings:
        changes = state_changes(self._scale(), data, desired)
        self.io_values = dict(changes.pop("values"))
        changes.update(self._control(changes))
        situation = (changes.get("remote"), self.io_values.get("ref_from_net"))
        if situation != self.situation:
            self.sources_due = self.situation is not None
            self.situation = situation
        failsafe, text = failsafe_of(self.p313, self.io_timeout)
        changes["failsafe"], changes["failsafe_text"] = failsafe, text
        return changes

    def _control(self, changes: Readings) -> Readings:
        """Whether the drive obeys the network's run commands (issue 32 item 6)."""
        pair = self._scale().pair
        if pair is AssemblyPair.EXTENDED:
            return {}  # Ctrl from Net is in assembly 71 (state_changes)
        if pair is AssemblyPair.BASIC:
            net = True if self.ctrl_from_net is None else self.ctrl_from_net
            return {"remote": net, "local_control": not net}
        # 150: b4 says which situation the drive is in; P229/P230 where its commands
        # come from in that situation (seed 4.2.4, 4.2.5: 2 = DeviceNet)
        source = self.params.get("P230" if changes.get("remote") else "P229")
        return {"local_control": source is not None and source != COMMANDS_DEVICENET}

    @property
    def values(self) -> dict[str, float | int]:
        return {**self.io_values, **self.params}

    def _scale(self) -> ProfileSettings:
        if self.settings is None:
            raise NotConfigured(f"drive {self.drive_id}: the maximum speed is not known yet")
        return self.settings

    # ---------------------------------------------------------------- connection

    async def on_connect(self, port: DrivePort) -> None:
        await self._check_assembly(port)
        self.p313 = await self._checked_read(port, P313)
        self.params["P313"] = self.p313
        self.io_timeout = port.io_timeout
        await self._read_all_sources(port)
        if self.opts.max_rpm_param is not None:
            await self._read_max_rpm(port, self.opts.max_rpm_param)
        for number, value in self.opts.startup_params:
            try:
                await self.write_param(port, number, 0, value)
            except ParameterError as exc:
                raise NotConfigured(
                    f"startup parameter P{number} = {value} refused: {exc.text}"
                ) from None
            back = await self._checked_read(port, number)
            if back != value & 0xFFFF:
                raise NotConfigured(
                    f"startup parameter P{number} reads back {back} after writing {value}"
                )
        await self._check_baud_rate(port)
        await self._read_status(port, (P070,))  # P081 is idle until I/O starts: read later

    def configured_text(self) -> str:
        p313 = "unknown" if self.p313 is None else value_text(P313_TEXT, self.p313)
        return (
            f"configured: assembly {self.opts.assembly.label}, "
            f"{self.opts.connection.value} I/O; P313 = {p313}"
        )

    async def poll_status(self, port: DrivePort) -> None:
        """P070, P081 and P313 every time; of the sources, those that say whether the drive
        obeys the network on the assembly pair in use (:data:`CONTROL_SOURCES`), and the
        others every :data:`SOURCES_EVERY` polls or at the next poll after the I/O showed
        the drive's situation changing (docs/decisions/0106)."""
        await self._read_status(port)
        # the keypad can change these while the drive runs (seed 4.1.3, 4.2)
        self.p313 = int(await self.read_param(port, P313, 0))
        self.params["P313"] = self.p313
        self.status_polls += 1
        if self.sources_due or self.status_polls >= SOURCES_EVERY:
            await self._read_all_sources(port)
        else:
            await self._read_sources(port, CONTROL_SOURCES[self.opts.assembly])

    async def _read_all_sources(self, port: DrivePort) -> None:
        """Every source; the count to the next such read starts once all were read (a
        read that failed part way is tried whole at the next poll)."""
        await self._read_sources(port, SOURCE_PARAMS)
        self.status_polls, self.sources_due = 0, False

    async def _read_sources(self, port: DrivePort, numbers: tuple[int, ...]) -> None:
        """The source parameters ``numbers`` of P220-P231 (seed 4.2: where commands,
        reference and direction come from), and on 20/70 Control Supervisor attribute 15
        Ctrl from Net (table 16; 70 has no such bit). A direction or reference that is not
        the network's is said in an event."""
        for number in numbers:
            name = f"P{number:03d}"
            value = int(await self.read_param(port, number, 0))
            old = self.params.get(name)
            self.params[name] = value
            note = SOURCE_NOTES.get((number, value))
            if note is not None and old != value:
                port.event(EventKind.CONFIG, f"{name} = {value}: {note}", **{name: value})
        if self.opts.assembly is AssemblyPair.BASIC:
            body = GetAttributeSingle(CipClass.CONTROL_SUPERVISOR, 1, CTRL_FROM_NET)
            try:
                self.ctrl_from_net = bool(reply_data(await port.request(body))[0])
            except (ParameterError, IndexError):
                self.ctrl_from_net = None

    def offline_note(self) -> str | None:
        if self.p313 is None:
            return None
        action = value_text(P313_TEXT, self.p313)
        return f"on its I/O timeout (E37) the drive applies P313 = {action}"

    def diagnostics(self) -> dict[str, Any]:
        return {
            "assembly": self.opts.assembly.label,
            "assembly_in_force": self.in_force,
            "p313": None if self.p313 is None else value_text(P313_TEXT, self.p313),
            **self.params,
        }

    async def _check_assembly(self, port: DrivePort) -> None:
        """The assembly pair in force must be the configured one, or no I/O.

        P710 is only what the drive will use after its next reset (seed 4.1.8 note), so
        the pair in force is read from the I/O connection itself: its produced and
        consumed connection paths (Connection 05h, seed tables 13-14). A P710 that
        differs while the pair in force is right is reported: the drive runs correctly
        until its next reset, and is refused then.
        """
        want = self.opts.assembly
        instance = _IO_INSTANCE[self.opts.connection]
        produced = await self._path_assembly(
            port, instance, objects.ConnectionAttribute.PRODUCED_PATH
        )
        consumed = await self._path_assembly(
            port, instance, objects.ConnectionAttribute.CONSUMED_PATH
        )
        p710 = await self._checked_read(port, P710)
        self.params["P710"] = p710
        stored = AssemblyPair.from_p710(p710)
        in_force = f"{consumed}/{produced}"
        self.in_force = in_force
        if (consumed, produced) != (want.output_instance, want.input_instance):
            raise NotConfigured(_assembly_problem(want, in_force, instance, p710, stored))
        if stored is not want:
            shown = stored.label if stored is not None else "none"
            port.event(
                EventKind.CONFIG,
                f"P710 = {p710} selects assembly {shown}, the config says {want.label}: "
                f"{want.label} is in force until the drive's next reset, then the drive "
                "will not be brought online (seed 4.1.8)",
                P710=p710,
            )

    async def _path_assembly(self, port: DrivePort, instance: int, attribute: int) -> int:
        """The Assembly instance a connection path of the I/O connection names; a path
        that names none (or cannot be read) leaves the pair in force unknown: refused."""
        where = f"Connection 05h instance {instance} attribute {attribute}"
        body = GetAttributeSingle(CipClass.CONNECTION, instance, attribute)
        try:
            data = reply_data(await port.request(body))
        except ParameterError as exc:
            raise NotConfigured(
                f"reading the assembly in force ({where}) refused: {exc.text}"
            ) from None
        try:
            assembly = objects.decode_path(data).assembly
        except DeviceNetDecodeError:
            assembly = None
        if assembly is None:
            shown = data.hex(" ") or "empty"
            raise NotConfigured(
                f"the assembly in force is unknown: {where} names no assembly ({shown})"
            )
        return assembly

    async def _check_baud_rate(self, port: DrivePort) -> None:
        """P702 against the line's expected rate (seed 4.1.6; effective after a reset).

        The drive talks now, so the rates match today; a P702 fixed to another rate
        means it will not come back after its next reset. Reported, not refused.
        """
        p702 = await self._checked_read(port, P702)
        self.params["P702"] = p702
        rate = P702_BAUD.get(p702)
        expected = port.bitrate
        if rate is not None and rate != expected:
            port.event(
                EventKind.CONFIG,
                f"P702 = {p702} sets {rate // 1000} kbit/s, the line is configured for "
                f"{expected // 1000} kbit/s (bus key 'bitrate'): the drive will not "
                "communicate after its next reset",
                P702=p702,
            )

    async def _checked_read(self, port: DrivePort, number: int) -> int:
        try:
            value = await self.read_param(port, number, 0)
        except ParameterError as exc:
            raise NotConfigured(f"reading P{number} refused: {exc.text}") from None
        return int(value)

    async def _read_max_rpm(self, port: DrivePort, number: int) -> None:
        rpm = await self._checked_read(port, number)
        if not 1 <= rpm <= SPEED_REF_MAX_RPM:
            raise NotConfigured(f"P{number} = {rpm} is not a usable maximum speed (rpm)")
        self.settings = _settings(self.opts, float(rpm))
        port.capabilities_changed()

    async def _read_status(self, port: DrivePort, numbers: tuple[int, ...] = (P070, P081)) -> None:
        """P070 and P081 (seed 4.1.1, 4.1.2) into the values, with an event on change."""
        for number in numbers:
            name = f"P{number:03d}"
            value = int(await self.read_param(port, number, 0))
            old = self.params.get(name)
            self.params[name] = value
            if old is not None and old != value:
                port.event(EventKind.BUS, _status_text(number, value), **{name: value})
        port.values_changed()

    # ---------------------------------------------------------------- parameters

    async def read_param(self, port: DrivePort, number: int, subindex: int) -> ParamValue:
        path = _path(number, subindex)
        response = await port.request(
            GetAttributeSingle(path.class_id, path.instance_id, path.attribute_id)
        )
        data = reply_data(response)
        try:
            return decode_parameter(data)
        except DeviceNetDecodeError as exc:
            raise ParameterError(f"bad reply: {exc.message}") from None

    async def write_param(
        self, port: DrivePort, number: int, subindex: int, value: ParamValue
    ) -> None:
        path = _path(number, subindex)
        if isinstance(value, float):
            if not value.is_integer():
                raise ParameterError(f"P{number}: CFW-08 parameters are integers, not {value}")
            value = int(value)
        try:
            data = encode_parameter(value)
        except FrameEncodeError:
            raise ParameterError(f"P{number}: {value} does not fit a 16-bit parameter") from None
        body = SetAttributeSingle(path.class_id, path.instance_id, path.attribute_id, data)
        reply_data(await port.request(body))

    # ---------------------------------------------------------------- standard objects

    async def read_object(
        self, port: DrivePort, class_id: int, instance_id: int, attribute_id: int
    ) -> AttributeValue:
        """Get_Attribute_Single on a standard object of seed tables 8-18, decoded with the
        table's type; an attribute the table marks Set only is refused here."""
        spec = _object_attribute(class_id, instance_id, attribute_id)
        if not spec.gettable:
            raise ParameterError(_rights_text(class_id, spec, "Set"))
        response = await port.request(GetAttributeSingle(class_id, instance_id, attribute_id))
        try:
            return decode_attribute(spec.kind, reply_data(response))
        except DeviceNetDecodeError as exc:
            raise ParameterError(f"bad reply: {exc.message}") from None

    async def write_object(
        self,
        port: DrivePort,
        class_id: int,
        instance_id: int,
        attribute_id: int,
        value: AttributeValue,
    ) -> None:
        """Set_Attribute_Single on a standard object of seed tables 8-18, encoded with the
        table's type; Get-only attributes are refused here, and so are the command
        attributes (run, direction, reference, network control, fault reset, assembly
        data): the drive takes its commands from the hub, never as a write (rule 1).
        The drive checks the value and answers with its CIP status."""
        spec = _object_attribute(class_id, instance_id, attribute_id)
        if not spec.settable:
            raise ParameterError(_rights_text(class_id, spec, "Get"))
        if (class_id, attribute_id) in COMMAND_ATTRIBUTES or class_id == CipClass.ASSEMBLY:
            raise ParameterError(
                f"{_object_name(class_id)} attribute {attribute_id} ({spec.name}) commands "
                "the drive: use the command service"
            )
        try:
            data = encode_attribute(spec.kind, value)
        except FrameEncodeError as exc:
            raise ParameterError(f"{spec.name}: {exc}") from None
        body = SetAttributeSingle(class_id, instance_id, attribute_id, data)
        reply_data(await port.request(body))


# ---------------------------------------------------------------- helpers

COMMANDS_DEVICENET = 2  # seed 4.2.4, 4.2.5: P229/P230 = 2 DeviceNet
CTRL_FROM_NET = 15  # Control Supervisor attribute 15, Get (seed table 16)
SOURCE_PARAMS = (220, 221, 222, 229, 230, 231)  # seed 4.2.1-4.2.6
# The sources that decide local control, read at every status poll: on 100/150 the command
# source of each situation (P229/P230, seed 4.2.4-4.2.5); 21/71 carries Ctrl from Net in
# its I/O and 20/70 reads the Control Supervisor's (every poll, _read_sources).
CONTROL_SOURCES: dict[AssemblyPair, tuple[int, ...]] = {
    AssemblyPair.BASIC: (),
    AssemblyPair.EXTENDED: (),
    AssemblyPair.WEG: (229, 230),
}
SOURCES_EVERY = 5  # status polls between reads of every source (10 s at the default 2 s)
SOURCE_NOTES: dict[tuple[int, int], str] = {
    # seed 4.2.6: the direction is fixed whatever the network asks
    (231, 0): "the drive always turns clockwise (forward), whatever the direction asked",
    (231, 1): (
        "the drive always turns counter-clockwise (reverse), whatever the direction asked: "
        "a forward run turns the motor in reverse"
    ),
    # seed 4.2.1: the situation is fixed or chosen off the network
    (220, 0): "always local: run commands come from P229's source",
    (220, 1): "always remote: run commands come from P230's source",
    (220, 2): "the keypad chooses local or remote",
    (220, 3): "the keypad chooses local or remote",
    (220, 4): "DI2-DI4 choose local or remote",
}


def _settings(opts: DriveOptions, max_rpm: float) -> ProfileSettings:
    return ProfileSettings(
        pair=opts.assembly,
        max_rpm=max_rpm,
        weg_speed_scale=opts.weg_speed_scale,
        at_reference_rpm=opts.at_reference_rpm,
    )


_IO_INSTANCE: dict[IoKind, int] = {
    IoKind.POLLED: objects.ConnectionInstance.POLL,  # seed table 13
    IoKind.COS: objects.ConnectionInstance.COS_CYCLIC,  # seed table 14
    IoKind.CYCLIC: objects.ConnectionInstance.COS_CYCLIC,
}


def _assembly_problem(
    want: AssemblyPair, in_force: str, instance: int, p710: int, stored: AssemblyPair | None
) -> str:
    text = (
        f"the drive's I/O uses assembly {in_force} (Connection 05h instance {instance} "
        f"paths), the config says {want.label}"
    )
    if stored is want:
        return (
            f"{text}; P710 = {p710} selects {want.label} but takes effect only after a "
            "reset of the drive (seed 4.1.8): reset or power-cycle it"
        )
    shown = stored.label if stored is not None else "none"
    return f"{text}; P710 = {p710} selects assembly {shown}"


def _path(number: int, subindex: int) -> AttributePath:
    if subindex:
        raise ParameterError("the CFW-08 has no parameter subindexes (use subindex 0)")
    try:
        return parameter_path(number)
    except ValueError as exc:
        raise ParameterError(str(exc)) from None


# Attributes of seed tables 16 and 17 that command the drive (Run1, Run2, NetCtrl,
# Fault Reset; NetRef, Speed Ref): only through the command path, never written as data.
COMMAND_ATTRIBUTES: frozenset[tuple[int, int]] = frozenset(
    {
        (CipClass.CONTROL_SUPERVISOR, 3),
        (CipClass.CONTROL_SUPERVISOR, 4),
        (CipClass.CONTROL_SUPERVISOR, 5),
        (CipClass.CONTROL_SUPERVISOR, 12),
        (CipClass.AC_DC_DRIVE, 4),
        (CipClass.AC_DC_DRIVE, 8),
    }
)


def _object_name(class_id: int) -> str:
    spec = STANDARD_OBJECTS[class_id]
    return f"{spec.name} ({class_id:02X}h)"


def _object_attribute(class_id: int, instance_id: int, attribute_id: int) -> AttributeSpec:
    """The attribute as seed tables 8-18 define it; ParameterError when they do not."""
    spec = STANDARD_OBJECTS.get(class_id)
    if spec is None:
        known = ", ".join(f"{c:02X}h" for c in STANDARD_OBJECTS)
        raise ParameterError(f"class {class_id:#04x} is not a CFW-08 object ({known})")
    if instance_id not in spec.instances:
        raise ParameterError(
            f"{_object_name(class_id)} has no instance {instance_id} ({spec.source})"
        )
    attr = spec.attributes.get(attribute_id)
    if attr is None:
        raise ParameterError(
            f"{_object_name(class_id)} has no attribute {attribute_id} ({spec.source})"
        )
    return attr


def _rights_text(class_id: int, attr: AttributeSpec, only: str) -> str:
    source = STANDARD_OBJECTS[class_id].source
    return (
        f"{_object_name(class_id)} attribute {attr.attribute} ({attr.name}) is {only} only "
        f"({source})"
    )


def _status_text(number: int, value: int) -> str:
    if number == P070:
        text = f"P070 CAN controller: {value_text(P070_TEXT, value)}"
        code = P070_COMM_ERROR.get(value)
        return f"{text} (E{code}: {fault_text(code)})" if code else text
    text = f"P081 network master: {value_text(P081_TEXT, value)}"
    return f"{text} (E36: {fault_text(36)})" if value == P081_IDLE else text


def seed_param_table() -> ParamTable:
    """The CFW-08 parameters the DeviceNet manual gives (seed section 4: P070, P081,
    P220-P231, P313, P700-P710, with their ranges): the drive's table when it has no EDS,
    so a parameter backup knows what to read (docs/devices.md)."""
    return param_table(
        ParamInfo(
            number=p.number,
            name=p.name,
            minimum=p.minimum,
            maximum=p.maximum,
            code=f"P{p.number:03d}",
        )
        for p in sorted(SEED_PARAMETERS.values(), key=lambda p: p.number)
    )
