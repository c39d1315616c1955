"""The simulated starter's data values (installation guide 4.3, table 6): the answer to a
data request of the Extended mode's monitoring bytes, with the guide's scales."""

from __future__ import annotations

from collections.abc import Callable
from typing import Final, Protocol

from adapters.mcd600.monitoring import (
    FOURTEEN_BITS,
    PRODUCT_TYPE_MCD600,
    DataRequest,
    MonitorReply,
    ScaledPower,
    StarterStateWord,
)
from adapters.mcd600.starter import SoftStarter, StarterSettings


class Monitored(Protocol):
    """What the data values read of the simulated starter."""

    @property
    def starter(self) -> SoftStarter: ...

    @property
    def current_x10(self) -> bool: ...

    @property
    def version(self) -> tuple[int, int]: ...

    @property
    def trip_code(self) -> int: ...

    @property
    def start_input(self) -> bool: ...

    @property
    def reset_input_closed(self) -> bool: ...

    @property
    def input_a(self) -> bool: ...

    @property
    def input_b(self) -> bool: ...

    def settings(self) -> StarterSettings: ...


def monitor_reply(sim: Monitored, number: int) -> MonitorReply:
    """The reply to data request ``number`` (an unknown one: the invalid bit, 4.3 table 5
    byte 3 bit 0)."""
    try:
        request = DataRequest(number)
    except ValueError:
        return MonitorReply(echo=number, invalid=True)
    value = _VALUES[request](sim)
    return MonitorReply(echo=number, value=value & 0xFFFF)


def _amps(sim: Monitored, amps: float, mask: int) -> int:
    return min(mask, round(amps * (10 if sim.current_x10 else 1)))


def _starter_state(sim: Monitored) -> int:
    s = sim.starter
    return StarterStateWord(
        state=int(s.state),
        positive_phase_sequence=True,
        current_above_flc=s.current_pct(sim.settings()) > 100.0,
        initialised=True,
        trip_code=sim.trip_code,
    ).encode()


def _digital_inputs(sim: Monitored) -> int:
    bits = (
        (sim.start_input, 0),
        (sim.reset_input_closed, 2),
        (sim.input_a, 3),
        (sim.input_b, 4),
    )
    return sum(1 << bit for closed, bit in bits if closed)


def _volts(sim: Monitored) -> int:
    return min(FOURTEEN_BITS, round(sim.starter.line_voltage))


_VALUES: Final[dict[DataRequest, Callable[[Monitored], int]]] = {
    DataRequest.PRODUCT: lambda sim: PRODUCT_TYPE_MCD600 << 8,
    DataRequest.STARTER_STATE: _starter_state,
    DataRequest.MOTOR_CURRENT: lambda sim: _amps(sim, sim.starter.current_a, 0xFFFF),
    DataRequest.MOTOR_TEMPERATURE: lambda sim: min(255, round(sim.starter.thermal_pct)),
    DataRequest.POWER_FACTOR: lambda sim: round(100 * sim.starter.power_factor),
    DataRequest.POWER_KW: lambda sim: ScaledPower.from_units(sim.starter.power_w).encode(),
    DataRequest.POWER_KVA: lambda sim: ScaledPower.from_units(
        sim.starter.apparent_power_va
    ).encode(),
    DataRequest.VOLTAGE: _volts,
    DataRequest.CURRENT_L1: lambda sim: _amps(sim, sim.starter.current_a, FOURTEEN_BITS),
    DataRequest.CURRENT_L2: lambda sim: _amps(sim, sim.starter.current_a, FOURTEEN_BITS),
    DataRequest.CURRENT_L3: lambda sim: _amps(sim, sim.starter.current_a, FOURTEEN_BITS),
    DataRequest.VOLTAGE_L1: _volts,
    DataRequest.VOLTAGE_L2: _volts,
    DataRequest.VOLTAGE_L3: _volts,
    DataRequest.VERSION: lambda sim: sim.version[0] << 8 | sim.version[1],
    DataRequest.DIGITAL_INPUTS: _digital_inputs,
}
