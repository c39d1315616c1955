"""MCD 600 trip codes and their texts (installation guide 4.5 "Códigos de desarme").

The texts are the guide's, translated to English. Codes 84 to 96 are one entry in the guide,
"Defeito interno x": internal fault x, to be reported to the supplier with its code.
A code the table does not list keeps its number and gets a text saying only that.
"""

from __future__ import annotations

from typing import Final

NO_TRIP: Final = 0
EXCESS_START_TIME: Final = 1
MOTOR_OVERLOAD: Final = 2
NETWORK_FORCED_TRIP: Final = 16  # the trip the card forces after the comm timeout (3.3)

TRIP_TEXTS: Final[dict[int, str]] = {  # guide 4.5, table of trip codes
    0: "No trip",
    1: "Excess start time",
    2: "Motor overload",
    3: "Motor thermistor",
    4: "Current imbalance",
    5: "Frequency",
    6: "Phase sequence",
    7: "Instantaneous overcurrent",
    8: "Power loss",
    9: "Undercurrent",
    10: "Heatsink overtemperature",
    11: "Motor connection",
    12: "Input A trip",
    13: "FLC too high",
    14: "Unsupported option (function not available in inside delta)",
    15: "Communications card fault",
    16: "Network forced trip",
    17: "Internal fault",
    18: "Overvoltage",
    19: "Undervoltage",
    23: "Parameter out of range",
    24: "Input B trip",
    26: "L1 phase loss",
    27: "L2 phase loss",
    28: "L3 phase loss",
    29: "L1-T1 shorted",
    30: "L2-T2 shorted",
    31: "L3-T3 shorted",
    33: "Time-overcurrent (bypass overload)",
    34: "SCR overtemperature",
    35: "Battery/clock",
    36: "Thermistor circuit",
    47: "Overpower",
    48: "Underpower",
    56: "LCP disconnected",
    57: "Zero speed detect",
    58: "SCR Itsm",
    59: "Instantaneous overcurrent",
    60: "Rating capacity",
    70: "Current read error L1",
    71: "Current read error L2",
    72: "Current read error L3",
    73: "Remove mains voltage (mains voltage connected in run simulation)",
    74: "Motor connection T1",
    75: "Motor connection T2",
    76: "Motor connection T3",
    77: "Firing fail P1",
    78: "Firing fail P2",
    79: "Firing fail P3",
    80: "VZC fail P1",
    81: "VZC fail P2",
    82: "VZC fail P3",
    83: "Low control volts",
}

INTERNAL_FAULTS: Final = range(84, 97)  # guide 4.5: "84-96 Defeito interno x"


def is_listed(code: int) -> bool:
    """True when the guide's table lists the code (84 to 96 included)."""
    return code in TRIP_TEXTS or code in INTERNAL_FAULTS


def trip_text(code: int) -> str:
    """The guide's text for a trip code; an unlisted code gets its number only."""
    text = TRIP_TEXTS.get(code)
    if text is not None:
        return text
    if code in INTERNAL_FAULTS:
        return f"Internal fault {code}: contact the local supplier and quote fault code {code}"
    return f"Trip code {code}"
