"""The simulated CFW-08, frame by frame: allocation and its rejections (fact sheet 2.5),
every attribute of the seed's tables with its access rights (seed 5), the WEG classes
(seed 5.10), EPR and inactivity (2.9) with the P313 action (seed 4.1.3), idle (E36),
reset offline (seed 3.4), bus-off (seed 4.1.7)."""

from __future__ import annotations

import pytest

from adapters.devicenet.cfw08 import In71, Out21, encode_parameter
from adapters.devicenet.cfw08.objects import STANDARD_OBJECTS, AttributeSpec, Kind, wire_size
from adapters.devicenet.codec.cip import GeneralStatus
from adapters.devicenet.codec.dupmac import DupMacCheck, DupMacKind
from adapters.devicenet.codec.explicit import (
    AllocateConnectionSet,
    AllocateResponse,
    Body,
    ErrorResponse,
    ExplicitMessage,
    GenericRequest,
    GetAttributeSingle,
    ReleaseConnectionSet,
    Reset,
    Response,
    SetAttributeSingle,
    SuccessResponse,
)
from adapters.devicenet.codec.fragment import (
    ExplicitFragment,
    ExplicitReassembler,
    ExplicitSender,
    FragmentAck,
    decode_explicit_frame,
)
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.objects import AllocationChoice, ConnectionState
from adapters.devicenet.sim.node import Cfw08Node, SimNodeConfig, SimPhase

MAC = 5
UNCONNECTED, REQUEST, RESPONSE, POLL = 0x42E, 0x42C, 0x42B, 0x42D  # fact sheet 2.1/2.2
POLL_RESPONSE = 0x3C5
EXPLICIT_POLL = AllocationChoice.EXPLICIT | AllocationChoice.POLL


class Master:
    """A minimal master driving one simulated node with a fake clock."""

    def __init__(self, node: Cfw08Node, mac: int = 0) -> None:
        self.node, self.mac, self.now = node, mac, 0.0
        self.sent: list[CanFrame] = []
        self.sent.extend(node.power_on(self.now))
        self.advance(2.5 * node.config.dupmac_timeout)
        assert node.phase is SimPhase.ONLINE

    def advance(self, seconds: float, step: float = 0.005) -> list[CanFrame]:
        out: list[CanFrame] = []
        end = self.now + seconds
        while self.now < end:
            self.now = min(end, self.now + step)
            out.extend(self.node.step(self.now))
        self.sent.extend(out)
        return out

    def frame(self, arbitration_id: int, data: bytes) -> list[CanFrame]:
        out = self.node.step(self.now, CanFrame(arbitration_id, data))
        self.sent.extend(out)
        return out

    def ask(self, body: Body, arbitration_id: int = REQUEST) -> Response:
        """One request and its reply, fragmenting both ways as needed (fact sheet 2.8)."""
        sender = ExplicitSender(ExplicitMessage(self.mac, False, body).encode())
        reassembler = ExplicitReassembler()
        todo = [sender.start(self.now)]
        while todo:
            replies = [
                f for f in self.frame(arbitration_id, todo.pop()) if f.arbitration_id == RESPONSE
            ]
            for reply in replies:
                frame = decode_explicit_frame(reply.data)
                if isinstance(frame, FragmentAck):
                    nxt = sender.on_ack(self.now, frame)
                    if nxt is not None:
                        todo.append(nxt)
                elif isinstance(frame, ExplicitFragment):
                    step = reassembler.feed(self.now, frame)
                    assert step.ack is not None
                    todo.append(step.ack.encode())
                    if step.message is not None:
                        return self._reply(step.message)
                else:
                    return self._reply(frame.message)
        raise AssertionError("no reply")

    def _reply(self, raw: bytes) -> Response:
        reply = ExplicitMessage.decode(raw)
        assert reply.mac == self.mac and not reply.is_request
        return reply.body  # type: ignore[return-value]

    def allocate(self, choice: int = EXPLICIT_POLL, epr_ms: int = 100) -> None:
        assert self.ask(
            AllocateConnectionSet(AC(choice), self.mac), UNCONNECTED
        ) == AllocateResponse(0)
        instance = 2 if choice & AllocationChoice.POLL else 4
        epr = epr_ms.to_bytes(2, "little")
        assert self.ask(SetAttributeSingle(5, instance, 9, epr)) == SuccessResponse(0x10, epr)


def node(**kw: object) -> Cfw08Node:
    return Cfw08Node(SimNodeConfig(MAC, dupmac_timeout=0.05, ramp_time=0.5, **kw))  # type: ignore[arg-type]


@pytest.fixture
def master() -> Master:
    return Master(node())


# ---------------------------------------------------------------- duplicate MAC (2.3)


def test_power_on_runs_the_duplicate_mac_check() -> None:
    n = node()
    first = n.power_on(0.0)
    assert [(f.arbitration_id, f.data.hex(" ")) for f in first] == [
        (0x42F, "00 55 03 05 00 00 08")  # request, WEG vendor 355h, serial 0x08000005
    ]
    assert n.step(0.04) == []
    second = n.step(0.05)
    assert second == first
    assert n.step(0.1) == [] and n.phase is SimPhase.ONLINE
    claim = DupMacCheck(MAC, DupMacKind.REQUEST, 0, 1, 2).to_frame()
    assert n.step(0.2, claim) == [
        DupMacCheck(MAC, DupMacKind.RESPONSE, 0, 0x355, 0x08000005).to_frame()
    ]


def test_a_taken_mac_stops_the_node() -> None:
    n = node()
    n.power_on(0.0)
    answer = DupMacCheck(MAC, DupMacKind.RESPONSE, 0, 0x355, 1).to_frame()
    assert n.step(0.01, answer) == []
    assert n.phase is SimPhase.MAC_FAULT
    assert n.step(1.0) == [] and n.next_deadline() is None


# ---------------------------------------------------------------- allocation (2.5)

AC = AllocationChoice


@pytest.mark.parametrize(
    ("choice", "status"),
    [
        (0x00, (0x09, 0x02)),  # zero
        (0x41, (0x09, 0x02)),  # ACK suppression without COS or cyclic
        (0x02, (0x09, 0x02)),  # explicit missing
        (0x31, (0x09, 0x02)),  # COS and cyclic together
        (0x05, (0x02, 0x02)),  # bit-strobe: unsupported (seed 2.1)
        (0x09, (0x02, 0x02)),  # multicast poll: unsupported
        (0x81, (0x02, 0x02)),  # unnamed bit
    ],
)
def test_allocation_rejections(master: Master, choice: int, status: tuple[int, int]) -> None:
    reply = master.ask(AllocateConnectionSet(AC(choice), 0), UNCONNECTED)
    assert reply == ErrorResponse(*status)


def test_allocation_accepts_cos_cyclic_and_ack_suppression(master: Master) -> None:
    for choice in (0x11, 0x21 | 0x40):
        assert master.ask(AllocateConnectionSet(AC(choice), 0), UNCONNECTED) == AllocateResponse(0)
        assert master.ask(ReleaseConnectionSet(AC(choice)), UNCONNECTED) == SuccessResponse(0x4C)


def test_already_allocated_and_owned_by_another_master(master: Master) -> None:
    master.allocate()
    assert master.ask(AllocateConnectionSet(EXPLICIT_POLL, 0), UNCONNECTED) == ErrorResponse(
        0x0B, 0x02
    )
    other = ExplicitMessage(9, False, AllocateConnectionSet(EXPLICIT_POLL, 9)).encode()
    out = master.frame(UNCONNECTED, other)
    assert ExplicitMessage.decode(out[0].data) == ExplicitMessage(
        9, False, ErrorResponse(0x0C, 0x01)
    )
    release = ExplicitMessage(9, False, ReleaseConnectionSet(EXPLICIT_POLL)).encode()
    out = master.frame(UNCONNECTED, release)
    assert ExplicitMessage.decode(out[0].data).body == ErrorResponse(0x0C, 0x01)
    # Allocation info (class 3 attribute 5): choice byte and master MAC (2.5).
    assert master.ask(GetAttributeSingle(3, 1, 5)) == SuccessResponse(0x0E, b"\x03\x00")
    assert master.ask(ReleaseConnectionSet(EXPLICIT_POLL), UNCONNECTED) == SuccessResponse(0x4C)
    assert master.node.allocation == 0 and master.node.allocation_info() == b"\x00\xff"


def test_other_services_on_the_unconnected_port(master: Master) -> None:
    assert master.ask(GetAttributeSingle(1, 1, 1), UNCONNECTED) == ErrorResponse(0x08, 0x03)


def test_malformed_requests_get_the_decoder_status(master: Master) -> None:
    master.allocate()
    out = master.frame(REQUEST, bytes.fromhex("00 0E 01 01"))  # Get without attribute
    assert ExplicitMessage.decode(out[0].data).body == ErrorResponse(0x13)
    out = master.frame(REQUEST, bytes.fromhex("00 0E 01 01 01 00"))
    assert ExplicitMessage.decode(out[0].data).body == ErrorResponse(0x15)


def test_explicit_requests_before_allocation_are_ignored(master: Master) -> None:
    assert (
        master.frame(REQUEST, ExplicitMessage(0, False, GetAttributeSingle(1, 1, 1)).encode()) == []
    )
    assert master.frame(POLL, bytes(4)) == []


# ---------------------------------------------------------------- objects (seed 5)


def _sample(kind: Kind, minimum: int | None) -> bytes:
    size = wire_size(kind)
    value = minimum or 0
    if size is None:
        return b"\x01\x00\x00\x00"
    return value.to_bytes(size, "little", signed=kind is Kind.INT)


ATTRIBUTES = [
    (spec.class_id, instance, attr)
    for spec in STANDARD_OBJECTS.values()
    for instance in spec.instances[:1]
    for attr in spec.attributes.values()
]


@pytest.mark.parametrize(
    ("class_id", "instance", "attr"),
    ATTRIBUTES,
    ids=[f"{c:02X}/{i}/{a.attribute}" for c, i, a in ATTRIBUTES],
)
def test_every_attribute_with_its_rights(
    master: Master, class_id: int, instance: int, attr: AttributeSpec
) -> None:
    master.allocate()
    got = master.ask(GetAttributeSingle(class_id, instance, attr.attribute))
    if attr.gettable:
        assert isinstance(got, SuccessResponse), got
        size = wire_size(attr.kind)
        if size is not None:
            assert len(got.data) == size
    else:
        assert got == ErrorResponse(GeneralStatus.SERVICE_NOT_SUPPORTED)
    value = _sample(attr.kind, attr.minimum)
    if class_id == 0x04 and instance == 20:
        value = bytes(4)  # the active pair is 21/71: instance 20 is not the one P710 selects
    put = master.ask(SetAttributeSingle(class_id, instance, attr.attribute, value))
    if not attr.settable:
        assert put == ErrorResponse(GeneralStatus.ATTRIBUTE_NOT_SETTABLE)
    elif class_id == 0x04:
        assert put == ErrorResponse(GeneralStatus.OBJECT_STATE_CONFLICT)
    else:
        assert isinstance(put, SuccessResponse), put


def test_identity_values(master: Master) -> None:
    master.allocate()
    expected = {
        1: b"\x55\x03",  # seed table 8: vendor 355h
        2: b"\x02\x00",  # product type 2h
        4: b"\x04\x06",
        6: (0x08000005).to_bytes(4, "little"),
        7: b"\x06CFW-08",  # fragmented reply (9 bytes)
    }
    for attribute, data in expected.items():
        assert master.ask(GetAttributeSingle(1, 1, attribute)) == SuccessResponse(0x0E, data)
    status = master.ask(GetAttributeSingle(1, 1, 5))
    assert isinstance(status, SuccessResponse) and status.data[0] & 0x01  # owned


@pytest.mark.parametrize(
    ("body", "status"),
    [
        (GetAttributeSingle(0x30, 1, 1), GeneralStatus.PATH_DESTINATION_UNKNOWN),
        (GetAttributeSingle(0x29, 2, 6), GeneralStatus.OBJECT_DOES_NOT_EXIST),
        (GetAttributeSingle(0x05, 3, 1), GeneralStatus.OBJECT_DOES_NOT_EXIST),  # no bit-strobe
        (GetAttributeSingle(0x29, 1, 13), GeneralStatus.ATTRIBUTE_NOT_SUPPORTED),
        (GetAttributeSingle(0x02, 1, 1), GeneralStatus.ATTRIBUTE_NOT_SUPPORTED),  # seed 5.2
        (GetAttributeSingle(0x03, 1, 3), GeneralStatus.ATTRIBUTE_NOT_SUPPORTED),  # not in table 9
        (SetAttributeSingle(0x28, 1, 3, b"\x0b"), GeneralStatus.INVALID_ATTRIBUTE_VALUE),  # 0-10
        (SetAttributeSingle(0x28, 1, 7, b"\x59\x02"), GeneralStatus.INVALID_ATTRIBUTE_VALUE),  # 601
        (SetAttributeSingle(0x2A, 1, 6, b"\x03"), GeneralStatus.INVALID_ATTRIBUTE_VALUE),  # 1-2
        (SetAttributeSingle(0x29, 1, 3, b"\x02"), GeneralStatus.INVALID_ATTRIBUTE_VALUE),  # BOOL
        (
            SetAttributeSingle(0x2A, 1, 8, b"\x10\x27"),
            GeneralStatus.INVALID_ATTRIBUTE_VALUE,
        ),  # 10000
        (SetAttributeSingle(0x2A, 1, 8, b"\x10"), GeneralStatus.NOT_ENOUGH_DATA),
        (SetAttributeSingle(0x2A, 1, 8, b"\x10\x00\x00"), GeneralStatus.TOO_MUCH_DATA),
        (SetAttributeSingle(0x01, 1, 1, b"\x01\x00"), GeneralStatus.ATTRIBUTE_NOT_SETTABLE),
        (SetAttributeSingle(0x04, 71, 3, bytes(4)), GeneralStatus.ATTRIBUTE_NOT_SETTABLE),
        (SetAttributeSingle(0x04, 21, 3, bytes(3)), GeneralStatus.NOT_ENOUGH_DATA),
        (GenericRequest(0x16, 0x01, 1), GeneralStatus.SERVICE_NOT_SUPPORTED),  # Save
        (Reset(0x29, 1), GeneralStatus.SERVICE_NOT_SUPPORTED),
    ],
)
def test_error_answers(master: Master, body: Body, status: int) -> None:
    master.allocate()
    assert master.ask(body) == ErrorResponse(status)


def test_control_through_the_standard_objects(master: Master) -> None:
    master.allocate(epr_ms=1000)
    for attribute, value in ((5, b"\x01"), (3, b"\x01")):
        assert master.ask(SetAttributeSingle(0x29, 1, attribute, value)) == SuccessResponse(0x10)
    assert master.ask(SetAttributeSingle(0x2A, 1, 4, b"\x01")) == SuccessResponse(0x10)
    assert master.ask(SetAttributeSingle(0x2A, 1, 8, (300).to_bytes(2, "little"))) == (
        SuccessResponse(0x10)
    )
    master.advance(1.0)
    assert master.ask(GetAttributeSingle(0x2A, 1, 7)) == SuccessResponse(0x0E, b"\x2c\x01")
    assert master.ask(GetAttributeSingle(0x29, 1, 6)) == SuccessResponse(0x0E, b"\x04")  # enabled
    assert master.ask(GetAttributeSingle(0x29, 1, 7)) == SuccessResponse(0x0E, b"\x01")
    assert master.ask(GetAttributeSingle(0x29, 1, 15)) == SuccessResponse(0x0E, b"\x01")


# ---------------------------------------------------------------- WEG classes (seed 5.10)


@pytest.mark.parametrize(
    ("body", "reply"),
    [
        (GetAttributeSingle(0x6B, 1, 110), SuccessResponse(0x0E, b"\x01\x00")),  # P710 = 1
        (GetAttributeSingle(0x6B, 1, 101), SuccessResponse(0x0E, b"\x05\x00")),  # P701 = MAC
        (GetAttributeSingle(0x67, 1, 113), SuccessResponse(0x0E, b"\x02\x00")),  # P313 default
        (SetAttributeSingle(0x67, 1, 113, b"\x01\x00"), SuccessResponse(0x10)),
        (SetAttributeSingle(0x67, 1, 113, b"\x04\x00"), ErrorResponse(0x09)),  # P313 0-3
        (SetAttributeSingle(0x64, 1, 170, b"\x00\x00"), ErrorResponse(0x0E)),  # P070 read-only
        (SetAttributeSingle(0x64, 1, 181, b"\x00\x00"), ErrorResponse(0x0E)),  # P081 read-only
        (GetAttributeSingle(0x64, 1, 199), ErrorResponse(0x14)),  # P099 not in the table
        (GetAttributeSingle(0x64, 1, 99), ErrorResponse(0x14)),  # attribute below 100
        (GetAttributeSingle(0x64, 2, 170), ErrorResponse(0x16)),  # only instance 1
        (SetAttributeSingle(0x67, 1, 113, b"\x01"), ErrorResponse(0x13)),
        (SetAttributeSingle(0x67, 1, 113, b"\x01\x00\x00"), ErrorResponse(0x15)),
    ],
)
def test_weg_classes(master: Master, body: Body, reply: Response) -> None:
    master.allocate()
    assert master.ask(body) == reply


def test_parameter_writes_take_effect(master: Master) -> None:
    master.allocate()
    assert master.ask(SetAttributeSingle(0x65, 1, 100, encode_parameter(20))) == SuccessResponse(
        0x10
    )
    assert master.node.drive.params[100] == 20
    master.advance(0.01)
    assert master.node.drive.motor.accel_time == 2.0


# ---------------------------------------------------------------- I/O, EPR, inactivity


def test_epr_is_rounded_up_to_the_tick(master: Master) -> None:
    master.ask(AllocateConnectionSet(EXPLICIT_POLL, 0), UNCONNECTED)
    reply = master.ask(SetAttributeSingle(5, 2, 9, (45).to_bytes(2, "little")))
    assert reply == SuccessResponse(0x10, (50).to_bytes(2, "little"))
    assert master.node.connections[2].state is ConnectionState.ESTABLISHED


def test_poll_before_the_epr_is_set_is_not_answered(master: Master) -> None:
    master.ask(AllocateConnectionSet(EXPLICIT_POLL, 0), UNCONNECTED)
    assert master.node.connections[2].state is ConnectionState.CONFIGURING
    assert master.frame(POLL, bytes(4)) == []


def test_polls_drive_the_motor_and_idle_sets_p081(master: Master) -> None:
    master.allocate()
    run = Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=900).encode()
    for _ in range(30):
        out = master.frame(POLL, run)
        master.advance(0.05)
    assert out[0].arbitration_id == POLL_RESPONSE
    status = In71.decode(out[0].data)
    assert status.running1 and status.at_reference and status.speed_rpm == 900
    assert master.node.drive.params[81] == 0
    master.frame(POLL, b"")  # idle (zero-length): seed 4.1.2 P081 = 1, E36
    master.advance(0.01)
    assert master.node.drive.params[81] == 1 and master.node.drive.comm_error == 36


@pytest.mark.parametrize(
    ("p313", "speed_after", "enabled_after"),
    [(0, 0.0, False), (1, None, False), (2, 900.0, True), (3, 0.0, False)],
)
def test_inactivity_applies_p313(p313: int, speed_after: float | None, enabled_after: bool) -> None:
    master = Master(node(p313=p313))
    master.allocate(epr_ms=50)
    run = Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=900).encode()
    for _ in range(30):
        master.frame(POLL, run)
        master.advance(0.04)
    assert master.node.drive.motor.speed == 900.0
    master.advance(0.25)  # no poll for more than 4 x 50 ms
    drive = master.node.drive
    assert master.node.connections[2].state is ConnectionState.TIMED_OUT
    assert drive.comm_error == 37 and "E37" in master.node.figures.notes
    master.advance(1.0)
    if speed_after is not None:
        assert drive.motor.speed == speed_after
    else:
        assert 0.0 < drive.motor.speed < 900.0  # coasting: slower than the ramp
    assert drive.motor.enabled is enabled_after
    assert master.frame(POLL, run) == []  # timed out: no answer until the master re-establishes


def test_explicit_connection_auto_deletes(master: Master) -> None:
    master.allocate(epr_ms=1000)
    master.advance(10.1, step=0.05)  # 4 x 2500 ms without an explicit request
    assert master.node.connections[1].state is ConnectionState.NON_EXISTENT
    assert not master.node.allocation & AllocationChoice.EXPLICIT


def test_cos_production_on_change_and_heartbeat() -> None:
    master = Master(node())
    master.ask(AllocateConnectionSet(AC(0x11), 0), UNCONNECTED)
    master.ask(SetAttributeSingle(5, 4, 9, (200).to_bytes(2, "little")))
    out = master.advance(0.5)
    productions = [f for f in out if f.arbitration_id == 0x345]
    assert 2 <= len(productions) <= 4  # heartbeat every 200 ms, nothing changed
    ack = master.frame(
        POLL, Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=900).encode()
    )
    assert ack[0] == CanFrame(POLL_RESPONSE, b"")  # the slave acknowledges our production
    assert [f.arbitration_id for f in ack[1:]] == [0x345]  # and produces: its state changed
    out = master.advance(0.3)
    assert len([f for f in out if f.arbitration_id == 0x345]) > 5  # changing while ramping


# ---------------------------------------------------------------- reset, bus-off


def test_fault_reset_takes_the_node_offline_for_a_moment(master: Master) -> None:
    master.allocate()
    master.node.inject_fault(21)
    out = master.frame(POLL, Out21().encode())
    assert In71.decode(out[0].data).faulted and master.node.drive.fault_code == 21
    out = master.frame(POLL, Out21(fault_reset=True).encode())
    assert len(out) == 1  # answered, then resetting
    assert master.node.phase is SimPhase.RESETTING and master.node.drive.fault_code is None
    assert master.frame(POLL, bytes(4)) == []
    out = master.advance(0.6)
    assert {f.arbitration_id for f in out} == {0x42F}  # back: Duplicate MAC ID check
    master.advance(0.2)
    assert master.node.phase is SimPhase.ONLINE and master.node.allocation == 0


def phase(n: Cfw08Node) -> SimPhase:
    """The node's phase, read through a call (it changes under mypy's eyes)."""
    return n.phase


def test_keypad_reset_clears_the_fault_through_the_same_reset(master: Master) -> None:
    """The keypad's reset, behind the master's back: offline for a moment (seed 3.4), then
    back with its commands cleared; the master's run bit, sent again, runs the drive."""
    master.allocate()
    run = Out21(run_fwd=True, net_ctrl=True, net_ref=True, speed_rpm=900).encode()
    master.frame(POLL, run)
    master.node.inject_fault(21, master.now)
    assert master.node.keypad_reset(master.now) == []
    assert phase(master.node) is SimPhase.RESETTING and master.node.drive.fault_code is None
    assert master.node.keypad_reset(master.now) == []  # nothing more to reset
    master.advance(0.8)
    assert phase(master.node) is SimPhase.ONLINE and master.node.drive.motor.speed == 0.0
    assert not master.node.drive.run_fwd  # cleared by the restart
    master.allocate()
    for _ in range(10):
        master.frame(POLL, run)
        master.advance(0.05)
    assert master.node.drive.motor.speed > 0.0  # the held run bit, sent again, runs it


def test_auto_reset_after_p206_seconds(master: Master) -> None:
    master.node.drive.params[206] = 2
    master.allocate(epr_ms=1000)
    master.node.inject_fault(21, master.now)
    fault_at = master.now
    assert master.node.auto_reset_due() == pytest.approx(fault_at + 2.0)
    assert master.node.next_deadline() == pytest.approx(fault_at + 2.0)
    master.advance(1.9, step=0.05)
    assert master.node.drive.fault_code == 21 and master.node.phase is SimPhase.ONLINE
    master.advance(0.2, step=0.05)
    assert master.node.drive.fault_code is None and master.node.phase is SimPhase.RESETTING
    assert any("auto-reset of E21" in n for n in master.node.figures.notes)
    off = Master(node())  # P206 = 0: no auto-reset
    off.node.inject_fault(21, off.now)
    off.advance(5.0, step=0.1)
    assert off.node.drive.fault_code == 21 and off.node.auto_reset_due() is None


def test_power_cycle_clears_a_fault() -> None:
    master = Master(node())
    master.node.inject_fault(21, master.now)
    master.node.power_off()
    master.node.power_on(master.now)
    assert master.node.drive.fault_code is None


def test_identity_reset_service(master: Master) -> None:
    master.allocate()
    assert master.ask(Reset(1, 1)) == SuccessResponse(0x05)
    assert master.node.phase is SimPhase.RESETTING


def test_bus_off_and_p703() -> None:
    master = Master(node())
    master.node.bus_off(master.now)
    assert master.node.drive.params[70] == 5 and master.node.next_deadline() is None  # P703 = 0
    assert master.advance(1.0) == []
    master.node.drive.params[703] = 1  # automatic reset
    master.node.bus_off(master.now, recover_after=0.1)
    out = master.advance(0.3)
    assert out and out[0].arbitration_id == 0x42F and master.node.drive.params[70] == 2


def test_p701_and_p700_take_effect_after_a_reset(master: Master) -> None:
    """Seed 4.1.4 and 4.1.5: the address and the protocol change only after a reset."""
    master.allocate()
    p701 = SetAttributeSingle(0x6B, 1, 101, encode_parameter(12))  # P701: class 107, attr 101
    assert master.ask(p701) == SuccessResponse(0x10)
    assert master.node.mac == MAC  # not yet
    assert master.ask(Reset(1, 1)) == SuccessResponse(0x05)
    out = master.advance(0.6)
    assert {f.arbitration_id for f in out} == {0x467}  # Duplicate MAC ID check of MAC 12
    assert out[0].data == DupMacCheck(12, DupMacKind.REQUEST, 0, 0x355, 0x08000005).encode_data()
    master.advance(0.2)
    assert master.node.phase is SimPhase.ONLINE and master.node.mac == 12
    assert master.frame(UNCONNECTED, bytes.fromhex("00 4b 03 01 03 00")) == []  # not MAC 5
    allocate = master.frame(0x466, bytes.fromhex("00 4b 03 01 03 00"))  # MAC 12's port
    assert [(f.arbitration_id, f.data.hex(" ")) for f in allocate] == [(0x463, "00 cb 00")]
    p700 = SetAttributeSingle(0x6B, 1, 100, encode_parameter(1))  # P700 = 1 CANopen
    request = ExplicitMessage(0, True, p700).encode()
    assert master.frame(0x464, request)[0].data == bytes.fromhex("40 90")
    assert master.node.reset(master.now) == []
    assert master.advance(1.0) == []  # not DeviceNet any more: silent
    phase: SimPhase = master.node.phase  # (not the phase mypy narrowed above)
    assert phase is SimPhase.NOT_DEVICENET and master.node.next_deadline() is None


def _paths(master: Master, instance: int = 2) -> tuple[str, str]:
    """Connection attributes 14 and 16 (seed tables 13-14), as hex."""
    out = []
    for attribute in (14, 16):
        reply = master.ask(GetAttributeSingle(5, instance, attribute))
        assert isinstance(reply, SuccessResponse)
        out.append(reply.data.hex(" "))
    return out[0], out[1]


def test_p710_takes_effect_after_a_reset_and_the_paths_show_the_pair_in_force(
    master: Master,
) -> None:
    """Seed 4.1.8 note: a P710 change counts only after a reset; the I/O connection's
    produced/consumed paths (tables 13-14) name the assembly in force."""
    master.allocate()
    assert _paths(master) == ("20 04 24 47 30 03", "20 04 24 15 30 03")  # 71 and 21
    p710 = SetAttributeSingle(0x6B, 1, 110, encode_parameter(0))  # P710 = 0: 20/70
    assert master.ask(p710) == SuccessResponse(0x10)
    assert master.node.drive.params[710] == 0
    assert _paths(master) == ("20 04 24 47 30 03", "20 04 24 15 30 03")  # still 21/71
    out = master.frame(POLL, Out21(run_rev=True, speed_rpm=300).encode())
    assert len(out[0].data) == 4 and master.node.drive.run_rev  # 21 is decoded as 21
    assert master.ask(Reset(1, 1)) == SuccessResponse(0x05)
    master.advance(0.8)
    master.allocate()
    assert _paths(master) == ("20 04 24 46 30 03", "20 04 24 14 30 03")  # 70 and 20
    assert _paths(master, 4) == ("20 04 24 46 30 03", "20 04 24 14 30 03")  # COS/cyclic too


def test_a_p710_changed_but_not_reset_at_start() -> None:
    """Config ``p710_stored``: the drive powers up with ``p710`` in force and P710 reads
    the other value until the next power cycle."""
    master = Master(node(p710=0, p710_stored=1))
    master.allocate()
    assert master.ask(GetAttributeSingle(0x6B, 1, 110)) == SuccessResponse(0x0E, b"\x01\x00")
    assert _paths(master) == ("20 04 24 46 30 03", "20 04 24 14 30 03")  # 20/70 in force
    master.node.power_off()
    master.sent.extend(master.node.power_on(master.now))
    master.advance(0.2)
    master.allocate()
    assert _paths(master) == ("20 04 24 47 30 03", "20 04 24 15 30 03")  # now 21/71
