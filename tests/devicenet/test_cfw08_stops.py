"""CFW-08 output assemblies on a quick stop or coast stop (issue 17 item 4).

Golden bytes: a stop goes with every run bit (Run Fwd / Run Rev of 20/21, Habilita Rampa
of 100) and JOG cleared. The CFW-08 assemblies have no quick stop (the hub refuses it by
capabilities); a desired quick stop that reaches the encoder anyway is a ramp stop, never
a run. Assembly 100 b1 Habilita Geral = 0 is the coast stop (seed table 7).
"""

from __future__ import annotations

from dataclasses import replace

import pytest

from adapters.devicenet.cfw08 import AssemblyPair, ProfileSettings, command_assembly
from gateway.model import DesiredCommand

RUN = DesiredCommand(run=True, speed_rpm=900.0)


@pytest.mark.parametrize(
    ("pair", "run", "quick", "coast"),
    [
        # seed table 5 (20): b0 Run Fwd; speed 900 rpm = 0x0384
        (AssemblyPair.BASIC, "01 00 84 03", "00 00 84 03", "00 00 84 03"),
        # seed table 6 (21): b0 Run Fwd, b5 NetCtrl, b6 NetRef
        (AssemblyPair.EXTENDED, "61 00 84 03", "60 00 84 03", "60 00 84 03"),
        # seed table 7 (100): b0 ramp, b1 general enable, b4 remote; 4096 counts = 900 rpm
        (AssemblyPair.WEG, "13 00 00 10", "12 00 00 10", "10 00 00 10"),
    ],
)
def test_stops_clear_run(pair: AssemblyPair, run: str, quick: str, coast: str) -> None:
    s = ProfileSettings(pair=pair)
    assert command_assembly(s, RUN, False).encode().hex(" ") == run
    q = replace(RUN, quick_stop=True)
    assert command_assembly(s, q, False).encode().hex(" ") == quick
    c = replace(RUN, coast_stop=True)
    assert command_assembly(s, c, False).encode().hex(" ") == coast


@pytest.mark.parametrize(
    "desired",
    [DesiredCommand(jog=True, quick_stop=True), DesiredCommand(jog=True, coast_stop=True)],
)
def test_stops_clear_jog_on_assembly_100(desired: DesiredCommand) -> None:
    s = ProfileSettings(pair=AssemblyPair.WEG)
    word = command_assembly(s, desired, False).encode()
    assert word[0] & 0x09 == 0  # b0 Habilita Rampa and b3 JOG off
