"""The address space of the drive model: Objects/Drives and Objects/Buses.

One object per drive, node ids readable and stable (``ns=<gateway>;s=<drive>.<Name>``)
so a SCADA's tag paths survive a restart:

- properties Device, Bus, Address, Firmware (the identity);
- the readings as AnalogItemType variables with EngineeringUnits (EUInformation, UNECE)
  and EURange (gateway/opcua/variables.py);
- status variables (comm, status, fault code and text, control source and client...);
- LastCommandResult: what the last method call on the drive got (accepted or the reason);
- methods Run, Stop, QuickStop, Reset, SetSpeed (gateway/opcua/commands.py);
- FaultAlarm: the condition its fault and trip alarms are raised on (gateway/opcua/alarms.py).

One object per line under Buses holds the line's figures as variables, made as they first
appear in its diagnostics. Nodes are added in one AddNodes request per drive.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from asyncua import Server, ua

from gateway.adapter import Capabilities
from gateway.model import DriveState
from gateway.opcua.variables import IDENTITY, READINGS, STATUS, UNECE_NAMESPACE, Kind, Range, Unit

NAMESPACE = "urn:drive-gateway:drives"
METHODS = ("Run", "Stop", "QuickStop", "Reset", "SetSpeed")
LAST_RESULT = "LastCommandResult"
ALARM = "FaultAlarm"
MAX_BUS_FIGURES = 64
"""Figures shown per line, at most (a line's diagnostics are bounded; this bounds the nodes)."""

_VARIANTS: dict[Kind, ua.VariantType] = {
    Kind.DOUBLE: ua.VariantType.Double,
    Kind.BOOLEAN: ua.VariantType.Boolean,
    Kind.STRING: ua.VariantType.String,
    Kind.INT32: ua.VariantType.Int32,
}
_DATATYPES: dict[Kind, int] = {
    Kind.DOUBLE: ua.ObjectIds.Double,
    Kind.BOOLEAN: ua.ObjectIds.Boolean,
    Kind.STRING: ua.ObjectIds.String,
    Kind.INT32: ua.ObjectIds.Int32,
}


@dataclass
class DriveNodes:
    """The node ids of one drive."""

    drive_id: str
    object: ua.NodeId
    variables: dict[str, ua.NodeId] = field(default_factory=dict)
    """Readings, status and LastCommandResult, by browse name."""
    kinds: dict[str, Kind] = field(default_factory=dict)
    ranges: dict[str, ua.NodeId] = field(default_factory=dict)
    """The EURange property of each reading, by the reading's browse name."""
    properties: dict[str, ua.NodeId] = field(default_factory=dict)
    methods: dict[str, ua.NodeId] = field(default_factory=dict)
    alarm: ua.NodeId | None = None


@dataclass
class BusNodes:
    name: str
    object: ua.NodeId
    figures: dict[str, ua.NodeId] = field(default_factory=dict)


class Builder:
    """Adds nodes to a server's address space (through its internal session)."""

    def __init__(self, server: Server, ns: int) -> None:
        self.server = server
        self.ns = ns
        self._pending: list[ua.AddNodesItem] = []

    def node_id(self, *parts: str) -> ua.NodeId:
        return ua.NodeId(".".join(parts), self.ns)

    def _item(
        self,
        parent: ua.NodeId,
        node: ua.NodeId,
        name: str,
        *,
        node_class: ua.NodeClass,
        ref: int,
        type_def: int | None,
        attrs: Any,
    ) -> None:
        item = ua.AddNodesItem()
        item.RequestedNewNodeId = node
        item.BrowseName = ua.QualifiedName(name, self.ns if ref != ua.ObjectIds.HasProperty else 0)
        item.NodeClass = node_class
        item.ParentNodeId = parent
        item.ReferenceTypeId = ua.NodeId(ref)
        if type_def is not None:
            item.TypeDefinition = ua.NodeId(type_def)
        attrs.DisplayName = ua.LocalizedText(name)
        attrs.Description = ua.LocalizedText(name)
        item.NodeAttributes = attrs
        self._pending.append(item)

    def object(
        self,
        parent: ua.NodeId,
        node: ua.NodeId,
        name: str,
        *,
        folder: bool = False,
        notifier: bool = False,
        history: bool = False,
    ) -> ua.NodeId:
        attrs = ua.ObjectAttributes()
        if notifier:
            attrs.EventNotifier = ua.EventNotifier.SubscribeToEvents.mask
        if notifier and history:  # its events are read back with HistoryRead
            attrs.EventNotifier |= ua.EventNotifier.HistoryRead.mask
        type_def = ua.ObjectIds.FolderType if folder else ua.ObjectIds.BaseObjectType
        ref = (
            ua.ObjectIds.Organizes
            if folder or parent.NamespaceIndex == 0
            else ua.ObjectIds.HasComponent
        )
        self._item(
            parent,
            node,
            name,
            node_class=ua.NodeClass.Object,
            ref=ref,
            type_def=type_def,
            attrs=attrs,
        )
        return node

    def variable(
        self,
        parent: ua.NodeId,
        node: ua.NodeId,
        name: str,
        value: ua.Variant,
        datatype: int | ua.NodeId,
        *,
        type_def: int = ua.ObjectIds.BaseDataVariableType,
        prop: bool = False,
        history: bool = False,
    ) -> ua.NodeId:
        attrs = ua.VariableAttributes()
        attrs.Value = value
        attrs.DataType = datatype if isinstance(datatype, ua.NodeId) else ua.NodeId(datatype)
        attrs.ValueRank = ua.ValueRank.Scalar
        access = ua.AccessLevel.CurrentRead.mask
        if history:
            access |= ua.AccessLevel.HistoryRead.mask
        attrs.AccessLevel = access
        attrs.UserAccessLevel = access
        attrs.Historizing = history
        attrs.MinimumSamplingInterval = 0.0
        attrs.WriteMask = 0
        attrs.UserWriteMask = 0
        ref = ua.ObjectIds.HasProperty if prop else ua.ObjectIds.HasComponent
        self._item(
            parent,
            node,
            name,
            node_class=ua.NodeClass.Variable,
            ref=ref,
            type_def=ua.ObjectIds.PropertyType if prop else type_def,
            attrs=attrs,
        )
        return node

    def method(self, parent: ua.NodeId, node: ua.NodeId, name: str) -> ua.NodeId:
        attrs = ua.MethodAttributes()
        attrs.Executable = True
        attrs.UserExecutable = True
        attrs.WriteMask = 0
        attrs.UserWriteMask = 0
        self._item(
            parent,
            node,
            name,
            node_class=ua.NodeClass.Method,
            ref=ua.ObjectIds.HasComponent,
            type_def=None,
            attrs=attrs,
        )
        return node

    def arguments(self, method: ua.NodeId, name: str, args: Iterable[ua.Argument]) -> None:
        listed = list(args)
        if not listed:
            return
        self.variable(
            method,
            ua.NodeId(f"{method.Identifier}.{name}", self.ns),
            name,
            ua.Variant(listed, ua.VariantType.ExtensionObject),
            ua.ObjectIds.Argument,
            prop=True,
        )

    async def commit(self) -> None:
        items, self._pending = self._pending, []
        if not items:
            return
        results = await self.server.iserver.isession.add_nodes(items)
        for item, result in zip(items, results, strict=True):
            if not result.StatusCode.is_good():
                raise RuntimeError(
                    f"OPC UA node {item.RequestedNewNodeId.to_string()} not added: "
                    f"{result.StatusCode.name}"
                )


def eu_information(unit: Unit) -> ua.EUInformation:
    return ua.EUInformation(
        NamespaceUri=UNECE_NAMESPACE,
        UnitId=unit.unit_id,
        DisplayName=ua.LocalizedText(unit.display),
        Description=ua.LocalizedText(unit.description),
    )


def eu_range(low_high: Range) -> ua.Variant:
    low, high = low_high
    return ua.Variant(ua.Range(Low=low, High=high), ua.VariantType.ExtensionObject)


def _argument(name: str, kind: Kind, description: str) -> ua.Argument:
    arg = ua.Argument()
    arg.Name = name
    arg.DataType = ua.NodeId(_DATATYPES[kind])
    arg.ValueRank = ua.ValueRank.Scalar
    arg.Description = ua.LocalizedText(description)
    return arg


INPUTS: Mapping[str, tuple[ua.Argument, ...]] = {
    "SetSpeed": (_argument("SpeedRpm", Kind.DOUBLE, "speed reference in rpm (negative: reverse)"),),
}
RESULT = _argument("Result", Kind.STRING, "accepted, or why the command was refused")


def initial_variant(kind: Kind) -> ua.Variant:
    defaults: dict[Kind, Any] = {
        Kind.DOUBLE: 0.0,
        Kind.BOOLEAN: False,
        Kind.STRING: "",
        Kind.INT32: 0,
    }
    return ua.Variant(defaults[kind], _VARIANTS[kind])


def variant(kind: Kind, value: Any) -> ua.Variant:
    return ua.Variant(value, _VARIANTS[kind])


async def add_drive(
    b: Builder, folder: ua.NodeId, state: DriveState, caps: Capabilities, history: bool
) -> DriveNodes:
    """One drive's object and everything in it (one AddNodes request)."""
    d = state.id
    nodes = DriveNodes(d, b.object(folder, b.node_id(d), d, notifier=True, history=history))
    identity: dict[str, ua.Variant] = {
        "Device": ua.Variant(state.device.value, ua.VariantType.String),
        "Bus": ua.Variant(state.bus, ua.VariantType.String),
        "Address": ua.Variant(state.address, ua.VariantType.Int32),
        "Firmware": ua.Variant("", ua.VariantType.String),
    }
    for name in IDENTITY:
        value = identity[name]
        datatype = ua.ObjectIds.Int32 if name == "Address" else ua.ObjectIds.String
        nodes.properties[name] = b.variable(
            nodes.object, b.node_id(d, name), name, value, datatype, prop=True
        )
    for reading in READINGS:
        node = b.node_id(d, reading.name)
        nodes.variables[reading.name] = b.variable(
            nodes.object,
            node,
            reading.name,
            initial_variant(Kind.DOUBLE),
            ua.ObjectIds.Double,
            type_def=ua.ObjectIds.AnalogItemType,
            history=history,
        )
        nodes.kinds[reading.name] = Kind.DOUBLE
        units = ua.Variant(eu_information(reading.unit), ua.VariantType.ExtensionObject)
        b.variable(
            node,
            b.node_id(d, reading.name, "EngineeringUnits"),
            "EngineeringUnits",
            units,
            ua.ObjectIds.EUInformation,
            prop=True,
        )
        nodes.ranges[reading.name] = b.variable(
            node,
            b.node_id(d, reading.name, "EURange"),
            "EURange",
            eu_range(reading.range_of(caps)),
            ua.ObjectIds.Range,
            prop=True,
        )
    for status in STATUS:
        nodes.variables[status.name] = b.variable(
            nodes.object,
            b.node_id(d, status.name),
            status.name,
            initial_variant(status.kind),
            _DATATYPES[status.kind],
        )
        nodes.kinds[status.name] = status.kind
    nodes.variables[LAST_RESULT] = b.variable(
        nodes.object,
        b.node_id(d, LAST_RESULT),
        LAST_RESULT,
        initial_variant(Kind.STRING),
        ua.ObjectIds.String,
    )
    nodes.kinds[LAST_RESULT] = Kind.STRING
    for name in METHODS:
        method = nodes.methods[name] = b.method(nodes.object, b.node_id(d, name), name)
        b.arguments(method, "InputArguments", INPUTS.get(name, ()))
        b.arguments(method, "OutputArguments", (RESULT,))
    nodes.alarm = b.object(nodes.object, b.node_id(d, ALARM), ALARM)
    await b.commit()
    return nodes


async def add_bus(b: Builder, folder: ua.NodeId, name: str) -> BusNodes:
    bus = BusNodes(name, b.object(folder, b.node_id("bus", name), name))
    await b.commit()
    return bus


async def add_bus_figure(b: Builder, bus: BusNodes, key: str) -> ua.NodeId | None:
    """A variable for a figure of the line first seen now (None past the bound)."""
    if len(bus.figures) >= MAX_BUS_FIGURES:
        return None
    node = b.variable(
        bus.object,
        b.node_id("bus", bus.name, key),
        key,
        ua.Variant(0.0, ua.VariantType.Double),
        ua.ObjectIds.Double,
    )
    await b.commit()
    bus.figures[key] = node
    return node
