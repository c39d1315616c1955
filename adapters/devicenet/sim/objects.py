"""The simulated CFW-08's explicit-message server: every attribute of the seed's tables
with its access rights, and the WEG parameter classes.

Answers (fact sheet 2.6 codes): unknown class 0x05 Path destination unknown; unknown
instance 0x16 Object does not exist; unknown attribute or parameter 0x14 Attribute not
supported; Set on a Get-only attribute 0x0E Attribute not settable; Get on a Set-only
attribute 0x08 Service not supported (decision: the seed marks Run1, Run2, NetCtrl and
Fault Reset "Set" only); value out of range 0x09 Invalid attribute value; too short
0x13, too long 0x15; other services 0x08.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol

from adapters.devicenet.cfw08 import decode_output, encode_parameter, parameter_of
from adapters.devicenet.cfw08.objects import (
    ASSEMBLY_INPUTS,
    STANDARD_OBJECTS,
    AttributeSpec,
    Value,
    decode_attribute,
    encode_attribute,
    wire_size,
)
from adapters.devicenet.codec.cip import CipClass, GeneralStatus, Service
from adapters.devicenet.codec.eds import Eds
from adapters.devicenet.codec.explicit import (
    ErrorResponse,
    GetAttributeSingle,
    Request,
    Reset,
    Response,
    SetAttributeSingle,
    SuccessResponse,
)
from adapters.devicenet.errors import AssemblyDecodeError, DataTypeDecodeError
from adapters.devicenet.sim.drive import SimDrive
from adapters.devicenet.sim.params import SIM_PARAMETERS

IDENTITY_OWNED = 0x0001  # fact sheet 2.12 status b0
IDENTITY_CONFIGURED = 0x0004  # b2
IDENTITY_MAJOR_RECOVERABLE = 0x0400  # b10


@dataclass(frozen=True, slots=True)
class Identity:
    vendor_id: int = 0x355  # seed table 8
    product_type: int = 0x2  # seed table 8
    product_code: int = 8  # not in the seed: simulator choice
    revision: tuple[int, int] = (4, 6)  # seed cover: software version 4.6X
    serial_number: int = 0
    product_name: str = "CFW-08"  # seed table 8


def identity_from_eds(eds: Eds) -> Identity:
    """The simulated drive's Identity object from an EDS's [Device] (the serial number
    stays the simulator's own)."""
    dev = eds.device
    return Identity(
        vendor_id=dev.vendor_code,
        product_type=dev.product_type,
        product_code=dev.product_code,
        revision=(dev.major_rev, dev.minor_rev),
        product_name=dev.product_name,
    )


class Connection(Protocol):
    """What the server reads and sets of a Connection object instance."""

    def attribute(self, attribute: int) -> Value: ...

    def set_epr(self, ms: int) -> int | None: ...  # None: the connection does not exist

    def set_inhibit(self, ms: int) -> bool: ...


class Context(Protocol):
    """The node the server answers for."""

    drive: SimDrive
    identity: Identity
    store: dict[tuple[int, int], int]

    def allocation_info(self) -> bytes: ...

    def allocated(self) -> bool: ...

    def connection(self, instance: int) -> Connection: ...

    def request_reset(self) -> None: ...


@dataclass(slots=True)
class _Answer:
    """A Set handler's outcome: an error, or the data of the success reply."""

    error: int | None = None
    data: bytes = b""


def _error(status: int) -> ErrorResponse:
    return ErrorResponse(status)


def handle(ctx: Context, request: Request) -> Response:
    """The reply to one explicit request."""
    if isinstance(request, GetAttributeSingle):
        return _get(ctx, request.class_id, request.instance_id, request.attribute_id)
    if isinstance(request, SetAttributeSingle):
        return _set(ctx, request)
    if isinstance(request, Reset) and request.class_id == CipClass.IDENTITY:
        if request.instance_id != 1:
            return _error(GeneralStatus.OBJECT_DOES_NOT_EXIST)
        ctx.request_reset()
        return SuccessResponse(Service.RESET)
    return _error(GeneralStatus.SERVICE_NOT_SUPPORTED)


# ---------------------------------------------------------------- WEG classes (seed 5.10)


def _parameter(class_id: int, instance: int, attribute: int) -> int | ErrorResponse:
    if instance != 1:  # seed 5.10 note: only instance 1
        return _error(GeneralStatus.OBJECT_DOES_NOT_EXIST)
    number = parameter_of(class_id, attribute)
    if number is None or number not in SIM_PARAMETERS:
        return _error(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED)
    return number


def _get_parameter(ctx: Context, class_id: int, instance: int, attribute: int) -> Response:
    number = _parameter(class_id, instance, attribute)
    if isinstance(number, ErrorResponse):
        return number
    return SuccessResponse(Service.GET_ATTRIBUTE_SINGLE, encode_parameter(ctx.drive.params[number]))


def _set_parameter(ctx: Context, request: SetAttributeSingle) -> Response:
    number = _parameter(request.class_id, request.instance_id, request.attribute_id)
    if isinstance(number, ErrorResponse):
        return number
    spec = SIM_PARAMETERS[number]
    if not spec.writable:
        return _error(GeneralStatus.ATTRIBUTE_NOT_SETTABLE)
    if len(request.value) < 2:
        return _error(GeneralStatus.NOT_ENOUGH_DATA)
    if len(request.value) > 2:
        return _error(GeneralStatus.TOO_MUCH_DATA)
    value = int.from_bytes(request.value, "little", signed=spec.minimum < 0)
    if not spec.minimum <= value <= spec.maximum:
        return _error(GeneralStatus.INVALID_ATTRIBUTE_VALUE)
    ctx.drive.params[number] = value
    return SuccessResponse(Service.SET_ATTRIBUTE_SINGLE)


def _is_weg(class_id: int) -> bool:
    return parameter_of(class_id, 100) is not None


# ---------------------------------------------------------------- standard objects


def _lookup(class_id: int, instance: int, attribute: int) -> AttributeSpec | ErrorResponse:
    spec = STANDARD_OBJECTS.get(class_id)
    if spec is None:
        return _error(GeneralStatus.PATH_DESTINATION_UNKNOWN)
    if instance not in spec.instances:
        return _error(GeneralStatus.OBJECT_DOES_NOT_EXIST)
    attr = spec.attributes.get(attribute)
    if attr is None:
        return _error(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED)
    return attr


def _get(ctx: Context, class_id: int, instance: int, attribute: int) -> Response:
    if _is_weg(class_id):
        return _get_parameter(ctx, class_id, instance, attribute)
    attr = _lookup(class_id, instance, attribute)
    if isinstance(attr, ErrorResponse):
        return attr
    if not attr.gettable:
        return _error(GeneralStatus.SERVICE_NOT_SUPPORTED)
    value = _GETTERS[class_id](ctx, instance, attribute)
    return SuccessResponse(Service.GET_ATTRIBUTE_SINGLE, encode_attribute(attr.kind, value))


def _set(ctx: Context, request: SetAttributeSingle) -> Response:
    class_id, instance, attribute = request.class_id, request.instance_id, request.attribute_id
    if _is_weg(class_id):
        return _set_parameter(ctx, request)
    attr = _lookup(class_id, instance, attribute)
    if isinstance(attr, ErrorResponse):
        return attr
    if not attr.settable:
        return _error(GeneralStatus.ATTRIBUTE_NOT_SETTABLE)
    size = wire_size(attr.kind)
    if size is not None and len(request.value) != size:
        short = len(request.value) < size
        return _error(GeneralStatus.NOT_ENOUGH_DATA if short else GeneralStatus.TOO_MUCH_DATA)
    try:
        value = decode_attribute(attr.kind, request.value)
    except DataTypeDecodeError:
        return _error(GeneralStatus.INVALID_ATTRIBUTE_VALUE)
    if isinstance(value, int) and not attr.in_range(value):
        return _error(GeneralStatus.INVALID_ATTRIBUTE_VALUE)
    answer = _SETTERS[class_id](ctx, instance, attribute, value)
    if answer.error is not None:
        return _error(answer.error)
    return SuccessResponse(Service.SET_ATTRIBUTE_SINGLE, answer.data)


# ---------------------------------------------------------------- per class

Getter = Callable[[Context, int, int], Value]
Setter = Callable[[Context, int, int, Value], _Answer]


def _identity_get(ctx: Context, _instance: int, attribute: int) -> Value:
    ident = ctx.identity
    status = IDENTITY_OWNED if ctx.allocated() else 0
    if ctx.drive.fault_code is not None:
        status |= IDENTITY_MAJOR_RECOVERABLE
    values: dict[int, Value] = {
        1: ident.vendor_id,
        2: ident.product_type,
        3: ident.product_code,
        4: ident.revision,
        5: status | IDENTITY_CONFIGURED,
        6: ident.serial_number,
        7: ident.product_name,
    }
    return values[attribute]


def _devicenet_get(ctx: Context, _instance: int, attribute: int) -> Value:
    if attribute == 5:
        return ctx.allocation_info()
    if attribute == 1:
        return ctx.drive.params[701]
    return ctx.store.get((CipClass.DEVICENET, attribute), 0)


def _store_set(ctx: Context, class_id: int, attribute: int, value: Value) -> _Answer:
    if isinstance(value, int):
        ctx.store[(class_id, attribute)] = value
    return _Answer()


def _devicenet_set(ctx: Context, _instance: int, attribute: int, value: Value) -> _Answer:
    if attribute == 1 and isinstance(value, int):
        ctx.drive.params[701] = value  # effective after a reset, as P701 (seed 4.1.5)
        return _Answer()
    return _store_set(ctx, CipClass.DEVICENET, attribute, value)


def _assembly_get(ctx: Context, instance: int, _attribute: int) -> Value:
    if instance in ASSEMBLY_INPUTS:
        return ctx.drive.input_data(instance)
    return ctx.store.get((CipClass.ASSEMBLY, instance), 0).to_bytes(4, "little")


def _assembly_set(ctx: Context, instance: int, _attribute: int, value: Value) -> _Answer:
    if instance in ASSEMBLY_INPUTS or not isinstance(value, bytes):
        return _Answer(GeneralStatus.ATTRIBUTE_NOT_SETTABLE)
    if instance != ctx.drive.pair.output_instance:
        return _Answer(GeneralStatus.OBJECT_STATE_CONFLICT)  # P710 selects another instance
    try:
        decode_output(instance, value)
    except AssemblyDecodeError:
        short = len(value) < 4
        return _Answer(GeneralStatus.NOT_ENOUGH_DATA if short else GeneralStatus.TOO_MUCH_DATA)
    ctx.drive.apply_output(value)
    ctx.store[(CipClass.ASSEMBLY, instance)] = int.from_bytes(value, "little")
    return _Answer()


def _connection_get(ctx: Context, instance: int, attribute: int) -> Value:
    return ctx.connection(instance).attribute(attribute)


def _connection_set(ctx: Context, instance: int, attribute: int, value: Value) -> _Answer:
    conn = ctx.connection(instance)
    if not isinstance(value, int):
        return _Answer(GeneralStatus.INVALID_ATTRIBUTE_VALUE)
    if attribute == 9:
        used = conn.set_epr(value)
        if used is None:
            return _Answer(GeneralStatus.OBJECT_STATE_CONFLICT)
        return _Answer(data=used.to_bytes(2, "little"))  # the EPR in use (fact sheet 2.10)
    if not conn.set_inhibit(value):
        return _Answer(GeneralStatus.OBJECT_STATE_CONFLICT)
    return _Answer()


def _motor_get(ctx: Context, _instance: int, attribute: int) -> Value:
    defaults = {3: 7, 6: round(ctx.drive.config.rated_current * 10), 7: 220}
    return ctx.store.get((CipClass.MOTOR_DATA, attribute), defaults[attribute])


def _motor_set(ctx: Context, _instance: int, attribute: int, value: Value) -> _Answer:
    return _store_set(ctx, CipClass.MOTOR_DATA, attribute, value)


def _supervisor_get(ctx: Context, _instance: int, attribute: int) -> Value:
    d = ctx.drive
    state = d.state
    values: dict[int, int] = {
        6: int(state),
        7: int(d.running_forward),
        8: int(d.running_reverse),
        9: int(state in (3, 4, 5)),
        10: int(d.fault_code is not None),
        11: 0,
        15: int(d.network_control),
    }
    return values[attribute]


def _supervisor_set(ctx: Context, _instance: int, attribute: int, value: Value) -> _Answer:
    d, on = ctx.drive, bool(value)
    d.forget_output()
    if attribute == 3:
        d.run_fwd = on
    elif attribute == 4:
        d.run_rev = on
    elif attribute == 5:
        d.net_ctrl = on
    elif attribute == 12:
        d.set_fault_reset_attribute(on)
    return _Answer()


def _drive_get(ctx: Context, _instance: int, attribute: int) -> Value:
    d = ctx.drive
    values: dict[int, int] = {
        4: int(d.net_ref),
        6: ctx.store.get((CipClass.AC_DC_DRIVE, 6), 2),
        7: min(d.speed_word, 9999),
        8: min(round(d.speed_ref_rpm), 9999),
    }
    return values[attribute]


def _drive_set(ctx: Context, _instance: int, attribute: int, value: Value) -> _Answer:
    d = ctx.drive
    d.forget_output()
    if attribute == 4:
        d.net_ref = bool(value)
    elif attribute == 8 and isinstance(value, int):
        d.speed_ref_rpm = float(value)
    else:
        return _store_set(ctx, CipClass.AC_DC_DRIVE, attribute, value)
    return _Answer()


def _ack_get(ctx: Context, _instance: int, attribute: int) -> Value:
    return ctx.store.get((CipClass.ACKNOWLEDGE_HANDLER, attribute), {1: 16, 2: 1, 3: 4}[attribute])


def _ack_set(ctx: Context, _instance: int, attribute: int, value: Value) -> _Answer:
    return _store_set(ctx, CipClass.ACKNOWLEDGE_HANDLER, attribute, value)


def _no_get(_ctx: Context, _instance: int, _attribute: int) -> Value:
    return 0


def _no_set(_ctx: Context, _instance: int, _attribute: int, _value: Value) -> _Answer:
    return _Answer(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED)


_GETTERS: Mapping[int, Getter] = {
    CipClass.IDENTITY: _identity_get,
    CipClass.MESSAGE_ROUTER: _no_get,
    CipClass.DEVICENET: _devicenet_get,
    CipClass.ASSEMBLY: _assembly_get,
    CipClass.CONNECTION: _connection_get,
    CipClass.MOTOR_DATA: _motor_get,
    CipClass.CONTROL_SUPERVISOR: _supervisor_get,
    CipClass.AC_DC_DRIVE: _drive_get,
    CipClass.ACKNOWLEDGE_HANDLER: _ack_get,
}

_SETTERS: Mapping[int, Setter] = {
    CipClass.IDENTITY: _no_set,
    CipClass.MESSAGE_ROUTER: _no_set,
    CipClass.DEVICENET: _devicenet_set,
    CipClass.ASSEMBLY: _assembly_set,
    CipClass.CONNECTION: _connection_set,
    CipClass.MOTOR_DATA: _motor_set,
    CipClass.CONTROL_SUPERVISOR: _supervisor_set,
    CipClass.AC_DC_DRIVE: _drive_set,
    CipClass.ACKNOWLEDGE_HANDLER: _ack_set,
}
