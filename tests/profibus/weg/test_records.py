"""Parameter access: the manuals' worked examples, verbatim, in both directions.

Gateway side: the profile's requests are the manuals' request bytes, and the manuals'
answers decode to the values or to ParameterError with the manual's text. Simulator side:
the simulated drive answers the manuals' requests with the manuals' answer bytes.
"""

from __future__ import annotations

import pytest

from adapters.profibus.codec import profidrive as pd
from adapters.profibus.contract import RecordAccessError
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.records import RecordParams
from adapters.profibus.weg.sim.drive import Cfw11Sim, Cfw320Sim, Cfw700Sim
from gateway.errors import GatewayTimeout, ParameterError
from gateway.model import Device
from tests.profibus.weg.helpers import SimChannel, profile


def b(*values: int) -> bytes:
    """Bytes as the manuals' tables list them (byte 1, byte 2, ...)."""
    return bytes(values)


# CFW-11 4.2.5 / CFW320 5.2.5, example 1: read P0002 (speed) and P0003 (current)
READ_P2_P3 = b(1, 1, 0, 2, 0x10, 1, 0, 2, 0, 0, 0x10, 1, 0, 3, 0, 0)
READ_P2_P3_OK = b(1, 1, 0, 2, 0x42, 1, 0, 100, 0x42, 1, 0, 50)  # P0002 = 100 rpm, P0003 = 5.0 A
READ_P2_P3_NOK = b(1, 129, 0, 2, 0x42, 1, 0, 100, 0x44, 1, 0, 0)  # 2nd: error 0000h
# CFW-11 4.2.5, example 2: change P0100 = 8.5 s
WRITE_P100 = b(1, 2, 0, 1, 0x10, 1, 0, 100, 0, 0, 0x42, 1, 0, 85)
WRITE_OK = b(1, 2, 0, 1)
WRITE_NOK = b(1, 130, 0, 2, 0x44, 1, 0, 2)  # as printed: 2 parameters, error 0002h
# CFW320 5.2.5, example 2: change P134 = 1000 rpm
WRITE_P134 = b(1, 2, 0, 1, 0x10, 1, 0, 134, 0, 0, 0x42, 1, 0x03, 0xE8)


class Scripted:
    """A RecordChannel answering DS_Read with scripted data (or errors), recording writes."""

    def __init__(self, *answers: bytes | Exception) -> None:
        self.answers = list(answers)
        self.writes: list[tuple[int, int, bytes]] = []
        self.reads: list[tuple[int, int, int]] = []

    async def write_record(self, slot: int, index: int, data: bytes) -> None:
        self.writes.append((slot, index, bytes(data)))

    async def read_record(self, slot: int, index: int, length: int) -> bytes:
        self.reads.append((slot, index, length))
        answer = self.answers.pop(0)
        if isinstance(answer, Exception):
            raise answer
        return answer


# ----------------------------------------------------------------- gateway side


async def test_read_p2_p3_request_and_positive_answer() -> None:
    ch = Scripted(READ_P2_P3_OK)
    assert await RecordParams().read_many(ch, [(2, 0), (3, 0)]) == [100, 50]
    assert ch.writes == [(0, 47, READ_P2_P3)]  # DS_Write slot 0 index 47
    assert ch.reads == [(0, 47, 240)]  # DS_Read of 240 bytes (4.2.3)


async def test_read_p2_p3_negative_answer_is_the_manuals_text() -> None:
    ch = Scripted(READ_P2_P3_NOK)
    with pytest.raises(ParameterError) as err:
        await RecordParams().read_many(ch, [(2, 0), (3, 0)])
    assert (err.value.text, err.value.code) == ("parameter does not exist", 0x0000)


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700])
async def test_write_p100_8_5_s_request_and_answers(device: Device) -> None:
    ch = Scripted(WRITE_OK)
    await profile(device).write_param(ch, 100, 0, 85)
    assert ch.writes == [(0, 47, WRITE_P100)]
    ch = Scripted(WRITE_NOK)
    with pytest.raises(ParameterError) as err:
        await profile(device).write_param(ch, 100, 0, 85)
    assert (err.value.text, err.value.code) == ("parameter value out of the limits", 2)


async def test_cfw320_write_p134_1000_request_and_answers() -> None:
    ch = Scripted(WRITE_OK)
    await profile(Device.CFW320).write_param(ch, 134, 0, 1000)
    assert ch.writes == [(0, 47, WRITE_P134)]
    with pytest.raises(ParameterError, match="out of the limits"):
        await profile(Device.CFW320).write_param(Scripted(WRITE_NOK), 134, 0, 1000)


async def test_read_retries_while_the_answer_is_not_available() -> None:
    # 4.2.4 step 3: "Caso a requisição não tenha sido processada ainda, o inversor
    # responderá erro na leitura. Esta leitura deve ser repetida" (C3h)
    busy = RecordAccessError("resource error", 0xC3)
    ch = Scripted(busy, busy, READ_P2_P3_OK)
    params = RecordParams(retry_delay=0.0)
    assert await params.read_many(ch, [(2, 0), (3, 0)]) == [100, 50]
    assert len(ch.reads) == 3
    with pytest.raises(GatewayTimeout):
        await RecordParams(retries=1, retry_delay=0.0).read_many(Scripted(busy, busy), [(2, 0)])


async def test_a_stale_answer_is_not_taken() -> None:
    stale = b(9, 1, 0, 1, 0x42, 1, 0, 7)
    ch = Scripted(stale, b(1, 1, 0, 1, 0x42, 1, 0, 8))
    assert await RecordParams(retry_delay=0.0).read(ch, 2) == 8


async def test_negative_dpv1_answer_has_the_weg_text() -> None:
    ch = Scripted(RecordAccessError("whatever the master says", 0xB8))
    with pytest.raises(ParameterError) as err:
        await RecordParams().read(ch, 2)
    assert err.value.text == "access error - invalid parameter number"
    assert err.value.code == 0xB8


async def test_record_48_read_is_write_2_bytes_then_read() -> None:
    ch = Scripted(b(0, 85))
    value = await profile(Device.CFW11, WegOptions(param_record=48)).read_param(ch, 100, 0)
    assert value == 85
    assert ch.writes == [(0, 48, b(0, 100))]
    assert ch.reads == [(0, 48, 240)]  # the 4.2.3 DS_Read asks for 240 bytes


async def test_record_48_write_is_4_bytes() -> None:
    ch = Scripted()
    await profile(Device.CFW320, WegOptions(param_record=48)).write_param(ch, 100, 0, 85)
    assert ch.writes == [(0, 48, b(0, 100, 0, 85))]
    with pytest.raises(ParameterError, match="no subindex"):
        await profile(Device.CFW320, WegOptions(param_record=48)).write_param(ch, 964, 1, 1)


async def test_values_are_raw_words() -> None:
    p = profile(Device.CFW11)
    with pytest.raises(ParameterError, match=r"8\.5 s is written as 85"):
        await p.write_param(Scripted(), 100, 0, 8.5)
    with pytest.raises(ParameterError, match="16-bit"):
        await p.write_param(Scripted(), 100, 0, 70000)
    ch = Scripted(WRITE_OK)
    await p.write_param(ch, 696, 0, -1)  # signed parameter: two's complement
    assert ch.writes[0][2][-2:] == b(0xFF, 0xFF)
    fresh = profile(Device.CFW11)
    assert await fresh.read_param(Scripted(b(1, 1, 0, 1, 0x42, 1, 0xFF, 0xFF)), 696, 0) == -1


# ----------------------------------------------------------------- simulator side


def ask(sim: Cfw11Sim | Cfw700Sim | Cfw320Sim, request: bytes) -> bytes:
    sim.write_record(0, 47, request, 0.0)
    return sim.read_record(0, 47, 240, 0.0)


@pytest.mark.parametrize("sim_class", [Cfw11Sim, Cfw700Sim, Cfw320Sim])
def test_sim_answers_the_read_example(sim_class: type[Cfw11Sim]) -> None:
    sim = sim_class()
    sim.pin(2, 100)  # "Supondo P0002 = 100 rpm e P0003 = 5,0 A"
    sim.pin(3, 50)
    assert ask(sim, READ_P2_P3) == READ_P2_P3_OK


def test_sim_answers_the_negative_read_example() -> None:
    # the second parameter does not exist: the answer is the manual's, byte for byte
    sim = Cfw11Sim()
    sim.pin(2, 100)
    request = pd.ParameterRequest.read(1, pd.ParameterAddress(2), pd.ParameterAddress(1198))
    assert ask(sim, request.encode()) == READ_P2_P3_NOK


def test_sim_answers_the_write_example_and_its_negative() -> None:
    sim = Cfw11Sim()
    assert ask(sim, WRITE_P100) == WRITE_OK
    assert sim.param(100) == 85
    out_of_range = pd.ParameterRequest.change(
        1, [(pd.ParameterAddress(100), pd.ValueBlock.word(10000))]
    )
    assert ask(sim, out_of_range.encode()) == WRITE_NOK
    assert sim.param(100) == 85


def test_cfw320_sim_answers_the_p134_example() -> None:
    sim = Cfw320Sim()
    assert ask(sim, WRITE_P134) == WRITE_OK
    assert sim.param(134) == 1000
    too_high = pd.ParameterRequest.change(
        1, [(pd.ParameterAddress(134), pd.ValueBlock.word(20000))]
    )
    assert ask(sim, too_high.encode()) == WRITE_NOK


def test_sim_record_47_errors() -> None:
    sim = Cfw700Sim()

    def code(request: pd.ParameterRequest) -> int | None:
        response = pd.ParameterResponse.decode(ask(sim, request.encode()))
        return response.values[0].error_number if response.values else None

    change = pd.ParameterRequest.change
    assert code(change(1, [(pd.ParameterAddress(2), pd.ValueBlock.word(1))])) == 0x0001
    assert code(change(1, [(pd.ParameterAddress(684), pd.ValueBlock.word(1))])) == 0x0001
    assert code(pd.ParameterRequest.read(1, pd.ParameterAddress(100, subindex=1))) == 0x0003
    assert code(pd.ParameterRequest.read(1, pd.ParameterAddress(100, elements=2))) == 0x0004
    assert code(pd.ParameterRequest.read(1, pd.ParameterAddress(964, subindex=4, elements=2))) == 3
    desc = pd.ParameterAddress(100, attribute=pd.Attribute.DESCRIPTION)
    assert code(pd.ParameterRequest.read(1, desc)) == 0x0009
    text = pd.ParameterAddress(100, attribute=pd.Attribute.TEXT)
    assert code(pd.ParameterRequest.read(1, text)) == 0x000F
    u16 = pd.ValueBlock(pd.DataFormat.UNSIGNED16, (5,))
    assert code(change(1, [(pd.ParameterAddress(100), u16)])) == 0x0005
    two = pd.ValueBlock.word(5, 6)
    assert code(change(1, [(pd.ParameterAddress(100), two)])) == 0x0018


def test_sim_p0964_array_and_p0965() -> None:
    sim = Cfw11Sim()
    request = pd.ParameterRequest.read(7, pd.ParameterAddress(964, 0, 5), pd.ParameterAddress(965))
    response = pd.ParameterResponse.decode(ask(sim, request.encode()))
    assert response.values[0].values[:3] == (367, 4, 500)  # manufacturer 367, type 4, P0023
    assert response.values[1].values == (809,)  # 3 << 8 | 41: PROFIdrive 4.1


def test_sim_several_changes_answer_per_parameter() -> None:
    sim = Cfw11Sim()
    request = pd.ParameterRequest.change(
        3,
        [
            (pd.ParameterAddress(100), pd.ValueBlock.word(50)),
            (pd.ParameterAddress(101), pd.ValueBlock.word(60000)),
        ],
    )
    response = pd.ParameterResponse.decode(ask(sim, request.encode()))
    assert response.response_id is pd.ResponseId.CHANGE_ERROR
    assert response.parameter_count == 2
    assert [v.format for v in response.values] == [pd.DataFormat.ZERO, pd.DataFormat.ERROR]
    assert sim.param(100) == 50


def test_sim_dpv1_errors() -> None:
    sim = Cfw11Sim()
    with pytest.raises(RecordAccessError) as err:
        sim.read_record(0, 47, 240, 0.0)  # nothing asked yet
    assert err.value.code_1 == 0xC3
    with pytest.raises(RecordAccessError) as err:
        sim.write_record(1, 47, READ_P2_P3, 0.0)
    assert err.value.code_1 == 0xB0
    with pytest.raises(RecordAccessError) as err:
        sim.write_record(0, 46, READ_P2_P3, 0.0)
    assert err.value.code_1 == 0xB2
    with pytest.raises(RecordAccessError) as err:
        sim.write_record(0, 47, b(1, 9, 0, 1), 0.0)  # no such request id
    assert (err.value.code_1, err.value.text) == (
        0xB7,
        "access error - incorrect values for parameter access",
    )


def test_sim_record_48_errors() -> None:
    sim = Cfw320Sim()

    def write(data: bytes) -> int | None:
        try:
            sim.write_record(0, 48, data, 0.0)
        except RecordAccessError as exc:
            return exc.code_1
        return None

    assert write(b(0, 100, 0, 85)) is None
    sim.write_record(0, 48, b(0, 100), 0.0)
    assert sim.read_record(0, 48, 2, 0.0) == b(0, 85)
    assert write(b(0, 2, 0, 1)) == 0xB6  # read-only
    assert write(b(0, 100, 0x27, 0x10)) == 0xB7  # 10000 > 999.0 s
    assert write(b(0x04, 0xAF, 0, 1)) == 0xB8  # P1199: no such parameter
    assert write(b(0x04, 0xAF)) == 0xB8
    assert write(b(1, 2, 3)) == 0xB7  # neither 2 nor 4 bytes
    with pytest.raises(RecordAccessError, match="response not available"):
        Cfw320Sim().read_record(0, 48, 2, 0.0)


async def test_busy_drive_is_read_again() -> None:
    sim = Cfw11Sim(busy_reads=2)
    ch = SimChannel(sim)
    assert await RecordParams(retry_delay=0.0).read(ch, 100) == 200
    assert len(ch.reads) == 3
