"""Parameter access and start-up through an in-memory RecordChannel to the simulated drive."""

from __future__ import annotations

import pytest

from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.programming import DriveProgrammingMismatch
from adapters.profibus.weg.spec import DataProfile
from gateway.errors import ParameterError
from gateway.model import Device, DriveStatus
from tests.profibus.weg.helpers import SIMS, Events, Loop, SimChannel, profile

MODELS = [Device.CFW11, Device.CFW700, Device.CFW320]
RECORDS = [47, 48]


@pytest.mark.parametrize("record", RECORDS)
@pytest.mark.parametrize("device", MODELS)
async def test_write_p100_85_then_read_it_back(device: Device, record: int) -> None:
    sim = SIMS[device]()
    ch = SimChannel(sim)
    p = profile(device, WegOptions(param_record=record))
    await p.write_param(ch, 100, 0, 85)
    assert await p.read_param(ch, 100, 0) == 85
    assert sim.param(100) == 85
    assert {index for _, index, _ in ch.writes} == {record}


@pytest.mark.parametrize(
    ("record", "text", "code"),
    [
        (47, "modification of read-only parameter", 0x0001),  # Table 4.2
        (48, "access error - modification in read-only parameter", 0xB6),  # 4.2.3
    ],
)
@pytest.mark.parametrize("device", MODELS)
async def test_read_only_write_is_refused(
    device: Device, record: int, text: str, code: int
) -> None:
    p = profile(device, WegOptions(param_record=record))
    with pytest.raises(ParameterError) as err:
        await p.write_param(SimChannel(SIMS[device]()), 3, 0, 10)
    assert (err.value.text, err.value.code) == (text, code)


@pytest.mark.parametrize(
    ("record", "text", "code"),
    [
        (47, "parameter value out of the limits", 0x0002),
        (48, "access error - incorrect values for parameter access", 0xB7),
    ],
)
async def test_out_of_range_is_refused(record: int, text: str, code: int) -> None:
    sim = SIMS[Device.CFW11]()
    p = profile(Device.CFW11, WegOptions(param_record=record))
    with pytest.raises(ParameterError) as err:
        await p.write_param(SimChannel(sim), 313, 0, 6)  # P0313: 0 to 5
    assert (err.value.text, err.value.code) == (text, code)
    assert sim.param(313) == 0


@pytest.mark.parametrize(
    ("record", "text"),
    [(47, "parameter does not exist"), (48, "access error - invalid parameter number")],
)
async def test_unknown_parameter(record: int, text: str) -> None:
    p = profile(Device.CFW320, WegOptions(param_record=record))
    with pytest.raises(ParameterError, match=text):
        await p.read_param(SimChannel(SIMS[Device.CFW320]()), 760, 0)  # CFW-11 only


@pytest.mark.parametrize(
    ("record", "text"),
    [
        (47, "incorrect access to the parameter"),
        (48, "access error - modification not allowed for the parameter"),
    ],
)
async def test_cfg_parameter_refused_while_running(record: int, text: str) -> None:
    loop = Loop(Device.CFW700, WegOptions(param_record=record))
    await loop.connect()
    loop.command(run=True, speed_rpm=600.0)
    loop.step(5)
    with pytest.raises(ParameterError, match=text):
        await loop.profile.write_param(loop.channel, 313, 0, 1)  # P0313 is CFG
    loop.command(run=False)
    loop.until(lambda s: s["status"] is DriveStatus.READY, 3.0)
    await loop.profile.write_param(loop.channel, 313, 0, 1)
    assert loop.sim.param(313) == 1


async def test_subindex_of_p0964() -> None:
    p = profile(Device.CFW11)
    assert await p.read_param(SimChannel(SIMS[Device.CFW11]()), 964, 1) == 4  # drive unit type
    with pytest.raises(ParameterError, match="sub-index does not exist"):
        await p.read_param(SimChannel(SIMS[Device.CFW11]()), 964, 5)


# ----------------------------------------------------------------- on_connect


@pytest.mark.parametrize("record", RECORDS)
async def test_startup_params_written_and_verified_at_connect(record: int) -> None:
    startup = ((313, 1), (100, 50), (101, 50))
    loop = Loop(Device.CFW11, WegOptions(param_record=record, startup_params=startup))
    await loop.connect()
    assert [loop.sim.param(n) for n, _ in startup] == [1, 50, 50]
    assert [text for text, kind, _ in loop.events.got] == [
        "startup P0313 = 1 written",
        "startup P0100 = 50 written",
        "startup P0101 = 50 written",
    ]
    assert all(kind == "parameter" for _, kind, _ in loop.events.got)
    loop.events.got.clear()
    loop.profile.on_comm_lost()
    await loop.connect()  # at every connect; already equal: read back only
    assert loop.events.got == []


async def test_startup_refusal_raises_from_on_connect() -> None:
    loop = Loop(Device.CFW320, WegOptions(startup_params=((313, 9),)))
    with pytest.raises(ParameterError) as err:
        await loop.connect()
    assert err.value.text == "startup P313 = 9: parameter value out of the limits"
    assert err.value.code == 2
    # the adapter's "not configured" reason
    assert str(err.value) == "startup P313 = 9: parameter value out of the limits (error 0x0002)"


async def test_startup_cfg_refused_while_running() -> None:
    loop = Loop(Device.CFW11, WegOptions(startup_params=((202, 1),)))
    await loop.connect()
    assert loop.sim.param(202) == 1
    loop.command(run=True, speed_rpm=600.0)
    loop.step(3)
    loop.sim.values[202] = 0  # changed at the HMI meanwhile
    with pytest.raises(ParameterError, match="startup P0202 = 1: incorrect access"):
        await loop.connect()


async def test_drive_programmed_differently_is_not_configured() -> None:
    loop = Loop(Device.CFW11, WegOptions(words=4, words_in=(3, 49)))
    loop.sim.values[743] = 48  # the drive maps P0048 in word 4
    loop.sim.values[741] = 0
    with pytest.raises(DriveProgrammingMismatch) as err:
        await loop.connect()
    # P0741 first, at every connect (issue 32 item 2), then the mapping
    assert str(err.value) == (
        "P0741 = 0 (profidrive), the config's data_profile is manufacturer (P0741 = 1): "
        "its words would be misread"
    )
    loop.sim.values[741] = 1
    loop.profile.on_comm_lost()  # the drive takes P0741 only out of data exchange
    loop.sim.set_prm(b"")
    with pytest.raises(DriveProgrammingMismatch) as err:
        await loop.connect()
    assert str(err.value) == (
        "the drive is programmed differently from its config: P0743 = 48 (config: 49)"
    )
    ok = Loop(Device.CFW11, WegOptions(words=4, words_in=(3, 49), verify_mapping=False))
    ok.sim.values[743] = 48
    await ok.connect()


async def test_cfw320_programming_parameters() -> None:
    loop = Loop(Device.CFW320, WegOptions(words=4, words_out=(100,), out_values=(20,)))
    await loop.connect()
    asked = {n for _, _, data in loop.channel.writes for n in _numbers(data)}
    assert {751, 742, 743, 746, 747} <= asked  # P751, P742-P743, P746-P747
    assert 741 in asked  # P741 read at connect: the words depend on it (Table 4.6 note)


def _numbers(request: bytes) -> list[int]:
    """Parameter numbers of a record 47 read request."""
    n = request[3]
    return [int.from_bytes(request[4 + 6 * i + 2 : 4 + 6 * i + 4], "big") for i in range(n)]


async def test_scales_are_read_at_connect() -> None:
    loop = Loop(Device.CFW700, params={403: 50, 402: 1450})
    assert (await loop.connect())["speed_base"] == "8192 = 1500 rpm synchronous"
    caps = loop.profile.capabilities()
    assert caps.speed_scale is not None and caps.speed_scale.base_rpm == 1500.0
    assert caps.speed_scale.max_pct == 120.0  # limited by P0134 = 1800 rpm
    loop.command(run=True, speed_rpm=750.0)
    s = loop.until(lambda s: s["at_reference"], 3.0)
    assert (s["speed_rpm"], s["speed_pct"]) == (750.0, 50.0)


async def test_configured_scales_are_not_read() -> None:
    options = WegOptions(sync_rpm=1800.0, max_rpm=1800.0, verify_mapping=False)
    loop = Loop(Device.CFW11, options)
    assert (await loop.connect())["speed_base"] == "8192 = 1800 rpm synchronous (configured)"
    # P0741 (data profile, every connect), P0202 (type of control, for the quick stop) and
    # P0313 and P0206 (reaction to a lost master): never a scale parameter
    assert loop.channel.writes[1] == (0, 47, bytes.fromhex("02 01 00 01 10 01 00 ca 00 00"))
    asked = [n for _, _, data in loop.channel.writes for n in _numbers(data)]
    assert asked == [741, 202, 313, 206]


async def test_profidrive_scale_follows_a_write_of_p0134() -> None:
    loop = Loop(Device.CFW11, WegOptions(data_profile=DataProfile.PROFIDRIVE))
    await loop.connect()
    await loop.profile.write_param(loop.channel, 134, 0, 1500)
    assert loop.profile.capabilities().speed_scale.base_rpm == 1500.0  # type: ignore[union-attr]
    loop.command(run=True, speed_rpm=750.0)
    s = loop.until(lambda s: s["status"] is DriveStatus.RUNNING, 3.0)
    # NSOLL 2000h of P0134 = 1500 rpm, converted by the drive into P0685 (13 bits)
    assert s["speed_rpm"] == pytest.approx(750.0, abs=0.2)
    assert loop.sim.motor.speed == pytest.approx(750.0, abs=0.2)


async def test_zero_rating_cannot_give_a_scale() -> None:
    loop = Loop(Device.CFW11, params={403: 0})
    with pytest.raises(DriveProgrammingMismatch, match="P0403 = 0"):
        await loop.connect()


async def test_cyclic_output_words_write_parameters() -> None:
    loop = Loop(Device.CFW11, WegOptions(words=3, words_out=(100,), out_values=(30,)))
    await loop.connect()
    loop.step()
    assert loop.sim.param(100) == 30  # word 3 -> P0750 = 100 -> P0100 = 3.0 s
    await loop.profile.write_param(loop.channel, 100, 0, 40)
    loop.step()
    assert loop.sim.param(100) == 40  # the cyclic word follows the parameter written


async def test_events_helper_records() -> None:
    events = Events()
    events("x", "parameter", number=1)
    assert events.got == [("x", "parameter", {"number": 1})]


async def test_cfw320_p741_profidrive_is_refused_at_connect() -> None:
    """CFW320 Table 4.6 note: the words "depend on the parameter P741". A drive set to
    PROFIdrive (P741 = 0) would be misread as the manufacturer's words: refused, even with
    verify_mapping off."""
    loop = Loop(Device.CFW320, WegOptions(verify_mapping=False))
    loop.sim.values[741] = 0
    with pytest.raises(DriveProgrammingMismatch) as info:
        await loop.connect()
    assert str(info.value) == (
        "P741 = 0 (profidrive), the config's data_profile is manufacturer (P741 = 1): "
        "its words would be misread"
    )
    ok = Loop(Device.CFW320, WegOptions(verify_mapping=False))
    await ok.connect()
    assert 741 in {n for _, _, data in ok.channel.writes for n in _numbers(data)}
