"""The WEG parameter tables (issue 20): names, units, decimal places and ranges as the seeds
give them, and the same tables reach the front ends through the drive's capabilities."""

from __future__ import annotations

import pytest

from adapters.profibus.weg.paramtable import NOT_IN_SEEDS, PARAM_TABLES
from adapters.profibus.weg.sim.params import PARAMETERS
from adapters.profibus.weg.spec import SPECS
from gateway.model import Device
from tests.profibus.weg.helpers import profile


def test_the_manuals_examples() -> None:
    cfw11 = PARAM_TABLES[Device.CFW11]
    # CFW-11 4.2.5 example 2: "P0100 = 8,5 s" is sent as 85; P0742: P0003 = 4.7 A is 47
    assert (cfw11[100].label, cfw11[100].name, cfw11[100].unit) == (
        "P0100",
        "Acceleration time",
        "s",
    )
    assert cfw11[100].scaled(85) == 8.5
    assert (cfw11[3].scaled(47), cfw11[3].unit) == (4.7, "A")
    assert cfw11[2].scaled(100) == 100  # P0002 = 100 rpm
    assert cfw11[799].scaled(9990) == 999.0 and (cfw11[799].minimum, cfw11[799].maximum) == (
        0.0,
        999.0,
    )
    # the CFW320 writes its numbers with 3 digits (P100, P750)
    cfw320 = PARAM_TABLES[Device.CFW320]
    assert (cfw320[100].label, cfw320[750].label) == ("P100", "P750")
    assert (cfw320[750].name, cfw320[750].minimum, cfw320[750].maximum) == (
        "Profibus address",
        1,
        126,
    )
    assert (cfw320[751].minimum, cfw320[751].maximum) == (1, 5)  # Table 4.7


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
def test_addresses_and_telegrams_agree_with_the_spec(device: Device) -> None:
    spec, table = SPECS[device], PARAM_TABLES[device]
    address = table[spec.address_param]
    assert (address.minimum, address.maximum) == spec.address_range
    telegram = table[spec.telegram_param]
    assert (telegram.minimum, telegram.maximum) == (1, spec.max_words - 1)
    assert NOT_IN_SEEDS[device] <= set(table)


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
def test_the_simulator_knows_every_parameter_of_the_table_within_its_range(
    device: Device,
) -> None:
    """The simulators follow the manuals: every parameter of the table exists there, and
    where the manual gives a range the simulator's writable range is inside it."""
    sim = PARAMETERS[device]
    for number, info in PARAM_TABLES[device].items():
        assert number in sim, info.label
        p = sim[number]
        if info.minimum is None or p.read_only or p.network_only:
            continue
        assert info.minimum <= info.scaled(p.low), info.label
        assert info.scaled(p.high) <= info.maximum, info.label  # type: ignore[operator]


@pytest.mark.parametrize("device", [Device.CFW11, Device.CFW700, Device.CFW320])
def test_the_profile_declares_its_table(device: Device) -> None:
    assert profile(device).capabilities().params is PARAM_TABLES[device]
