"""The simulated CiA 402 drive driven by the canopen library's own client (RemoteNode) on
python-can ``virtual``: NMT, SDO expedited and segmented with the CiA 301 abort codes,
PDO mapping by SDO (and a refused one), SYNC and event TPDOs, heartbeat, EMCY, the CiA 402
transitions over PDO, the 0x6007 reactions, and the fault injection."""

from __future__ import annotations

import struct

import canopen
import pytest
from canopen.objectdictionary import ODVariable
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from adapters.canopen.codec.cia402 import DeviceCommand, State, controlword, decode_state
from adapters.canopen.sim import BootState, SimNodeConfig
from tests.canopen.sim.conftest import EDS, Rig

OD = canopen.import_od(str(EDS), 5)

NODE = 5
HB = 0x700 + NODE
EMCY = 0x80 + NODE
VL_RUN = 0x70


def state_of(node: canopen.RemoteNode) -> State:
    return decode_state(node.sdo[0x6041].raw)


async def test_boot_up_and_heartbeat_in_pre_operational(rig: Rig) -> None:
    c = rig.client
    await c.until(lambda: len(c.seen(HB)) >= 2)
    assert c.seen(HB)[0] == b"\x00"  # boot-up
    assert c.seen(HB)[1] == b"\x7f"  # heartbeat: pre-operational
    assert rig.runner.node(NODE).nmt_state.name == "PRE_OPERATIONAL"


async def test_nmt_commands(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    node.nmt.send_command(0x01)  # start
    await c.until(lambda: c.seen(HB)[-1:] == [b"\x05"])
    node.nmt.send_command(0x02)  # stop: no SDO, heartbeat says stopped
    await c.until(lambda: c.seen(HB)[-1:] == [b"\x04"])
    with pytest.raises(SdoCommunicationError):
        await c.call(lambda: node.sdo[0x1000].raw)
    c.clear()
    node.nmt.send_command(0x81)  # reset node: boot-up, then pre-operational
    await c.until(lambda: b"\x00" in c.seen(HB) and c.seen(HB)[-1:] == [b"\x7f"])
    node.nmt.send_command(0x80)
    assert await c.call(lambda: node.sdo[0x1000].raw) == 0x00010192


async def test_nmt_to_another_node_is_ignored(rig: Rig) -> None:
    c = rig.client
    c.send(0x000, bytes([0x01, 6]))  # start node 6
    await c.until(lambda: len(c.seen(HB)) >= 3)
    assert rig.runner.node(NODE).nmt_state.name == "PRE_OPERATIONAL"


async def test_sdo_expedited_and_segmented(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    assert await c.call(lambda: node.sdo[0x1000].raw) == 0x00010192
    assert await c.call(lambda: node.sdo[0x1018][2].raw) == 0x402
    # 17 characters: a segmented upload
    assert await c.call(lambda: node.sdo[0x1008].raw) == "CiA402 test drive"
    # a segmented download of a 4-byte value, read back expedited
    await c.call(lambda: node.sdo.download(0x6083, 0, struct.pack("<I", 1234), True))
    assert await c.call(lambda: node.sdo[0x6083].raw) == 1234


@pytest.mark.parametrize(
    ("index", "subindex", "value", "code"),
    [
        (0x2001, 0, 1, 0x06020000),  # object does not exist
        (0x6046, 9, 1, 0x06090011),  # sub-index does not exist
        (0x6041, 0, 1, 0x06010002),  # read-only
        (0x605A, 0, 3, 0x06090030),  # value not supported (current limit)
        (0x6060, 0, 1, 0x06090030),  # profile position: not this drive's
        (0x6046, 2, 7000, 0x06090031),  # above HighLimit
        (0x6075, 0, 1, 0x06090032),  # below LowLimit
        (0x1600, 1, 0x60070010, 0x06040041),  # 0x6007 is not mappable
        (0x1600, 1, 0x60410010, 0x06040041),  # read-only statusword into an RPDO
        (0x1600, 1, 0x60400020, 0x06040041),  # wrong length
        (0x1A00, 1, 0x20010010, 0x06020000),  # no such object to map
        (0x1800, 2, 245, 0x06090030),  # reserved transmission type
    ],
)
async def test_sdo_abort_codes(rig: Rig, index: int, subindex: int, value: int, code: int) -> None:
    c = rig.client
    size = 4
    if index in OD and index not in (0x1600, 0x1A00, 0x6046):
        obj = OD[index]
        size = len(obj if isinstance(obj, ODVariable) else obj[subindex]) // 8
    data = struct.pack("<I", value)[:size]
    with pytest.raises(SdoAbortedError) as err:
        await c.call(c.remote(NODE).sdo.download, index, subindex, data)
    assert err.value.code == code


async def test_mapping_too_long_is_refused_and_changes_nothing(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)

    def configure() -> None:
        node.sdo[0x1A01][0].raw = 0
        for sub in range(1, 4):
            node.sdo[0x1A01][sub].raw = 0x606C0020  # 3 x 32 bits
        node.sdo[0x1A01][0].raw = 3

    with pytest.raises(SdoAbortedError) as err:
        await c.call(configure)
    assert err.value.code == 0x06040042
    assert await c.call(lambda: node.sdo[0x1A01][0].raw) == 0


async def test_pdo_mapping_by_sdo_and_sync_tpdo(rig: Rig) -> None:
    """The library's own PDO configuration (save() over SDO), pv mode, TPDO on SYNC."""
    c, node = rig.client, rig.client.remote(NODE)

    def configure() -> None:
        node.sdo[0x6060].raw = 3  # profile velocity
        node.tpdo.read()
        node.rpdo.read()
        tpdo = node.tpdo[1]
        tpdo.clear()
        tpdo.add_variable(0x6041)
        tpdo.add_variable(0x606C)
        tpdo.add_variable(0x6078)
        tpdo.trans_type = 1
        tpdo.enabled = True
        tpdo.save()
        rpdo = node.rpdo[1]
        rpdo.clear()
        rpdo.add_variable(0x6040)
        rpdo.add_variable(0x60FF)
        rpdo.trans_type = 255
        rpdo.enabled = True
        rpdo.save()
        node.nmt.state = "OPERATIONAL"

    await c.call(configure)
    assert await c.call(lambda: node.sdo[0x1A00][0].raw) == 3
    assert await c.call(lambda: node.sdo[0x1A00][2].raw) == 0x606C0020
    rpdo = node.rpdo[1]

    def command(word: int, rpm: int) -> None:
        rpdo[0x6040].raw = word
        rpdo[0x60FF].raw = rpm
        rpdo.transmit()

    sent = len(c.seen(0x180 + NODE))
    for word in (0x06, 0x07, 0x0F):
        command(word, 600)
    await c.until(lambda: rig.runner.node(NODE).drive.state is State.OPERATION_ENABLED)
    assert len(c.seen(0x180 + NODE)) == sent  # synchronous: nothing without SYNC
    c.network.sync.transmit()
    await c.until(lambda: len(c.seen(0x180 + NODE)) > sent)
    data = c.seen(0x180 + NODE)[-1]
    assert len(data) == 8
    status, _velocity, _current = struct.unpack("<HiH", data)
    assert decode_state(status) is State.OPERATION_ENABLED
    await c.until(lambda: rig.runner.node(NODE).drive.velocity_actual == 600)
    c.network.sync.transmit()
    await c.until(lambda: struct.unpack("<HiH", c.seen(0x180 + NODE)[-1])[1] == 600)


async def test_refused_mapping_through_the_library_save(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)

    def configure() -> None:
        node.rpdo.read()
        rpdo = node.rpdo[2]
        rpdo.clear()
        rpdo.add_variable(0x6040)
        rpdo.add_variable(0x605A)  # not mappable in this EDS
        rpdo.save()

    with pytest.raises(SdoAbortedError) as err:
        await c.call(configure)
    assert err.value.code == 0x06040041


async def test_event_tpdo_and_402_transitions_over_rpdo(rig: Rig) -> None:
    """The EDS's default mapping: RPDO1 controlword + vl target, TPDO1 statusword + vl
    actual, event-driven with a 100 ms event timer."""
    c, node = rig.client, rig.client.remote(NODE)
    await c.call(lambda: node.nmt.send_command(0x01))
    sim = rig.runner.node(NODE)
    await c.until(lambda: sim.nmt_state.name == "OPERATIONAL")
    await c.until(lambda: len(c.seen(0x180 + NODE)) >= 1)

    def rpdo(word: int, rpm: int) -> None:
        c.send(0x200 + NODE, struct.pack("<Hh", word, rpm))

    def tpdo() -> tuple[int, int]:
        status, rpm = struct.unpack("<Hh", c.seen(0x180 + NODE)[-1])
        return status, rpm

    rpdo(0x06, 0)
    await c.until(lambda: decode_state(tpdo()[0]) is State.READY_TO_SWITCH_ON)
    rpdo(0x07, 0)
    await c.until(lambda: decode_state(tpdo()[0]) is State.SWITCHED_ON)
    rpdo(0x0F | VL_RUN, 900)
    await c.until(lambda: decode_state(tpdo()[0]) is State.OPERATION_ENABLED)
    await c.until(lambda: tpdo()[1] == 900, seconds=3.0)
    assert tpdo()[0] & 0x0400  # target reached
    rpdo(0x0F | VL_RUN, -300)  # reverse
    await c.until(lambda: tpdo()[1] == -300, seconds=3.0)
    rpdo(0x02, -300)  # quick stop (0x605A = 2: quick stop ramp, then switch on disabled)
    await c.until(lambda: decode_state(tpdo()[0]) is State.SWITCH_ON_DISABLED)
    assert tpdo()[1] == 0


async def test_heartbeat_period_follows_0x1017(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    await c.call(lambda: node.sdo[0x1017].__setattr__("raw", 0))
    c.clear()
    sim = rig.runner.node(NODE)
    assert sim.next_deadline() is None
    await c.call(lambda: node.sdo[0x1017].__setattr__("raw", 20))
    await c.until(lambda: len(c.seen(HB)) >= 3)
    task = sim.periodic[HB]
    assert task.period == 0.02
    assert c.seen(HB)[-1] == b"\x7f"


async def test_emcy_on_fault_and_reset_on_the_edge(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    rig.runner.node(NODE).inject_fault(0x2310)
    await c.until(lambda: len(c.seen(EMCY)) >= 1)
    assert c.seen(EMCY)[0] == bytes([0x10, 0x23, 0x03, 0, 0, 0, 0, 0])
    assert await c.call(lambda: node.sdo[0x603F].raw) == 0x2310
    assert await c.call(lambda: node.sdo[0x1001].raw) == 0x03
    assert await c.call(state_of, node) is State.FAULT
    await c.call(lambda: node.sdo[0x6040].__setattr__("raw", 0x80))  # rising edge from 0
    assert await c.call(state_of, node) is State.SWITCH_ON_DISABLED
    await c.until(lambda: len(c.seen(EMCY)) >= 2)
    assert c.seen(EMCY)[1] == bytes(8)  # error reset
    assert await c.call(lambda: node.sdo[0x2000][3].raw) == 0x2310  # last fault kept


@pytest.mark.parametrize(
    ("option", "state", "emcy"),
    [
        (0, State.OPERATION_ENABLED, None),
        (1, State.FAULT, 0x8130),
        (2, State.SWITCH_ON_DISABLED, None),
        (3, State.SWITCH_ON_DISABLED, None),  # quick stop, then 12 (0x605A = 2)
    ],
)
async def test_0x6007_on_master_heartbeat_loss(
    rig: Rig, option: int, state: State, emcy: int | None
) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    sim = rig.runner.node(NODE)

    def configure() -> None:
        node.sdo[0x6007].raw = option
        node.sdo[0x1016][1].raw = (0x7F << 16) | 100  # master 127, 100 ms
        for word in (0x06, 0x07, 0x0F | VL_RUN):
            node.sdo[0x6040].raw = word

    await c.call(configure)
    assert sim.drive.state is State.OPERATION_ENABLED
    c.send(0x77F, b"\x05")  # the master's heartbeat arms the consumer
    await c.until(lambda: sim.next_deadline() is not None and sim._hb_watch.last is not None)
    c.send(0x77F, b"\x05")
    # then silence: after 100 ms the reaction
    await c.until(lambda: sim._hb_watch.fired, seconds=2.0)
    await c.until(lambda: sim.drive.state is state, seconds=2.0)
    if emcy is None:
        assert c.seen(EMCY) == []
    else:
        await c.until(lambda: len(c.seen(EMCY)) >= 1)
        assert struct.unpack_from("<H", c.seen(EMCY)[0])[0] == emcy
        assert await c.call(lambda: node.sdo[0x603F].raw) == emcy


async def test_rpdo_deadline_monitoring(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    sim = rig.runner.node(NODE)
    await c.call(lambda: node.sdo[0x1400][5].__setattr__("raw", 100))
    await c.call(lambda: node.nmt.send_command(0x01))
    await c.until(lambda: sim.nmt_state.name == "OPERATIONAL")
    c.send(0x200 + NODE, struct.pack("<Hh", 0x06, 0))
    await c.until(lambda: sim.drive.state is State.READY_TO_SWITCH_ON)
    await c.until(lambda: sim.drive.state is State.FAULT, seconds=2.0)
    await c.until(lambda: len(c.seen(EMCY)) >= 1)
    assert struct.unpack_from("<H", c.seen(EMCY)[0])[0] == 0x8250


async def test_silence_is_a_pulled_cable(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    sim = rig.runner.node(NODE)
    await c.until(lambda: len(c.seen(HB)) >= 2)
    sim.silence()
    c.clear()
    with pytest.raises(SdoCommunicationError):
        await c.call(lambda: node.sdo[0x1000].raw)
    assert c.seen(HB) == []
    sim.silence(False)
    await c.until(lambda: len(c.seen(HB)) >= 1)
    assert await c.call(lambda: node.sdo[0x1000].raw) == 0x00010192


async def test_sdo_refused_or_late(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    sim = rig.runner.node(NODE)
    sim.refuse_sdo()
    with pytest.raises(SdoCommunicationError):
        await c.call(lambda: node.sdo[0x1000].raw)
    sim.refuse_sdo(False)
    sim.delay_sdo(0.1)
    node.sdo.RESPONSE_TIMEOUT = 2.0
    assert await c.call(lambda: node.sdo[0x1000].raw) == 0x00010192


async def test_power_cycle_boots_again_with_defaults(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    sim = rig.runner.node(NODE)
    await c.call(lambda: node.sdo[0x6007].__setattr__("raw", 3))
    sim.inject_fault(0x5000)
    c.clear()
    sim.power_cycle()
    await c.until(lambda: len(c.seen(HB)) >= 1)
    assert c.seen(HB)[0] == b"\x00"
    assert await c.call(lambda: node.sdo[0x6007].raw) == 1
    assert await c.call(state_of, node) is State.SWITCH_ON_DISABLED


@pytest.mark.parametrize(
    "sim_nodes",
    [[SimNodeConfig(5, heartbeat_ms=50), SimNodeConfig(6, boot_state=BootState.OPERATIONAL)]],
)
async def test_two_nodes_one_bus(rig: Rig) -> None:
    c = rig.client
    assert await c.call(lambda: c.remote(6).sdo[0x1000].raw) == 0x00010192
    assert await c.call(lambda: c.remote(5).sdo[0x1018][2].raw) == 0x402
    assert rig.runner.node(6).nmt_state.name == "OPERATIONAL"  # a self-starting node
    await c.until(lambda: len(c.seen(0x186)) >= 1)  # its event TPDO
    c.send(0x000, bytes([0x81, 6]))
    await c.until(
        lambda: rig.runner.node(6).nmt_state.name == "OPERATIONAL" and b"\x00" in c.seen(0x706)
    )


def test_controlword_helper_matches_vl_run() -> None:
    assert controlword(DeviceCommand.ENABLE_OPERATION, extra=VL_RUN) == 0x7F


async def test_dropped_frames_are_lost_deterministically(rig: Rig) -> None:
    c, node = rig.client, rig.client.remote(NODE)
    sim = rig.runner.node(NODE)
    sim.drop_frames(1.0)
    with pytest.raises(SdoCommunicationError):
        await c.call(lambda: node.sdo[0x1000].raw)
    sim.drop_frames(0.0)
    assert await c.call(lambda: node.sdo[0x1000].raw) == 0x00010192
