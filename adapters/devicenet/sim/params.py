"""The simulated CFW-08's parameter table: the seed's DeviceNet parameters plus a few
the simulator needs for its physics.

The seed (section 4) gives P070, P081, P220-P231, P313 and P700-P710. The others below
are simulator assumptions taken from the CFW-08 user manual's numbering, not from the
seed: P003 motor current (0.1 A), P100/P101 acceleration/deceleration time (0.1 s),
P206 auto-reset time (s, 0 = off), P402 motor rated speed (rpm). A parameter not in this
table answers "Attribute not supported" (0x14), as an unknown attribute of a WEG class.
"""

from __future__ import annotations

from collections.abc import Mapping

from adapters.devicenet.cfw08.objects import SEED_PARAMETERS, ParamSpec

SIM_ASSUMED = "simulator assumption (CFW-08 user manual numbering, not in the seed)"

SIM_PARAMETERS: Mapping[int, ParamSpec] = {
    **SEED_PARAMETERS,
    3: ParamSpec(3, "motor current (0.1 A)", 0, 9999, None, False, SIM_ASSUMED),
    100: ParamSpec(100, "acceleration time (0.1 s)", 1, 9990, 50, True, SIM_ASSUMED),
    101: ParamSpec(101, "deceleration time (0.1 s)", 1, 9990, 50, True, SIM_ASSUMED),
    402: ParamSpec(402, "motor rated speed (rpm)", 0, 9999, 1720, True, SIM_ASSUMED),
    # 0 = off; the simulator resets any fault after P206 s, through the reset the seed
    # describes (3.4: offline for a moment)
    206: ParamSpec(206, "auto-reset time (s)", 0, 255, 0, True, SIM_ASSUMED),
}
