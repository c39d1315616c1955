"""Bus parameters of a Profibus DP line: baud rates, TSL, TSDR, TSYN and telegram times.

Pure data and arithmetic from the fact sheet (``reference/protocol-facts.md``) 1.1: the
standard baud rates, the default bus parameters per baud rate (bit times), the constraints
between them, 11 bits per character and the 33-bit idle time (TSYN) before every request.
The master engine turns them into seconds with :class:`BusParams`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

BAUD_RATES: Final = (
    9600,
    19200,
    45450,
    93750,
    187500,
    500000,
    1500000,
    3000000,
    6000000,
    12000000,
)
"""1.1: the Profibus DP baud rates, bit/s."""

BITS_PER_CHAR: Final = 11  # 1.1: start, 8 data, even parity, stop
TSYN_BITS: Final = 33  # 1.1: idle bit times before every request
TSL_MAX: Final = 16383  # 1.1: TSL <= 16383
MIN_TSDR_LOW: Final = 11  # 1.1: 11 <= min TSDR
MIN_TSDR_MAX: Final = 255  # 1.6: min TSDR is Set_Prm byte 3
TSL_OVER_MAX_TSDR: Final = 15  # 1.1: max TSDR + 15 <= TSL
RETRIES_RANGE: Final = (1, 15)  # 1.1: retries 1-15, default 1
MAX_TELEGRAM: Final = 255  # 1.2: SD2 with LE 249 is 255 bytes on the line
GC_PERIOD_TSL: Final = 50  # 1.9: profirust resends Global_Control every 50 x TSL


@dataclass(frozen=True)
class BusDefaults:
    """Default bus parameters for a baud rate, in bit times (fact sheet 1.1 table)."""

    tsl: int
    min_tsdr: int
    max_tsdr: int


def defaults_for(baudrate: int) -> BusDefaults:
    """1.1 table: <=187.5k TSL 100 / max TSDR 60, 500k 200/100, 1.5M 300/150, ..."""
    if baudrate <= 187500:
        return BusDefaults(100, 11, 60)
    table = {
        500000: BusDefaults(200, 11, 100),
        1500000: BusDefaults(300, 11, 150),
        3000000: BusDefaults(400, 11, 250),
        6000000: BusDefaults(600, 11, 450),
    }
    return table.get(baudrate, BusDefaults(1000, 11, 800))  # 12 Mbit/s


@dataclass(frozen=True)
class BusParams:
    """What the master engine needs to know about its line (times in seconds unless bits).

    ``latency`` is added to every reply wait: the delay of the serial converter and the
    operating system (a USB converter's latency timer, a pty's other end) that TSL, being
    a bus-level figure, does not cover.
    """

    baudrate: int = 500000
    master_address: int = 2
    tsl: int = 200  # slot time, bit times
    min_tsdr: int = 11  # bit times, sent in Set_Prm byte 3
    max_tsdr: int = 100  # bit times
    retries: int = 1  # repeats after the first try
    latency: float = 0.01
    cycle_time: float = 0.0  # a cycle starts at most this often (0 = back to back)
    absent_retry: float = 1.0  # an absent slave is probed this often
    fault_retry: float = 2.0  # a slave with a Cfg/Prm fault is started up again this often
    acyclic_timeout: float = 1.0  # bound of one DP-V1 read or write
    live_list_period: float = 0.0  # one FDL status probe of an unconfigured address (0 = off)
    gc_period: float | None = None  # Global_Control resend period (None = 50 x TSL)

    @classmethod
    def for_baudrate(cls, baudrate: int, **changes: object) -> BusParams:
        """Parameters with the fact sheet's defaults for ``baudrate``, then ``changes``."""
        d = defaults_for(baudrate)
        values: dict[str, object] = {
            "baudrate": baudrate,
            "tsl": d.tsl,
            "min_tsdr": d.min_tsdr,
            "max_tsdr": d.max_tsdr,
        }
        values.update(changes)
        return cls(**values)  # type: ignore[arg-type]

    @property
    def t_bit(self) -> float:
        return 1.0 / self.baudrate

    @property
    def slot_time(self) -> float:
        """TSL in seconds."""
        return self.tsl * self.t_bit

    @property
    def tsyn(self) -> float:
        """The idle time before every request, seconds (1.1: 33 bit times)."""
        return TSYN_BITS * self.t_bit

    def tx_time(self, n_bytes: int) -> float:
        """Time on the line of ``n_bytes`` characters (1.1: bytes x 11 x t_bit)."""
        return n_bytes * BITS_PER_CHAR * self.t_bit

    @property
    def reply_wait(self) -> float:
        """How long the first byte of a reply may take after the request's last byte."""
        return self.slot_time + self.latency

    @property
    def global_control_period(self) -> float:
        return self.gc_period if self.gc_period is not None else GC_PERIOD_TSL * self.slot_time


def bus_problems(params: BusParams) -> list[tuple[str, str]]:
    """(key, reason) for every constraint of fact sheet 1.1 that ``params`` breaks."""
    problems: list[tuple[str, str]] = []
    if params.baudrate not in BAUD_RATES:
        shown = ", ".join(str(b) for b in BAUD_RATES)
        problems.append(("baudrate", f"{params.baudrate} is not a Profibus DP baud rate ({shown})"))
    if not MIN_TSDR_LOW <= params.min_tsdr <= params.max_tsdr - 1:
        problems.append(
            (
                "min_tsdr",
                f"{params.min_tsdr} is outside {MIN_TSDR_LOW}..max_tsdr - 1 "
                f"({params.max_tsdr - 1})",
            )
        )
    if params.min_tsdr > MIN_TSDR_MAX:
        problems.append(
            ("min_tsdr", f"{params.min_tsdr} does not fit Set_Prm byte 3 (at most 255)")
        )
    low = params.max_tsdr + TSL_OVER_MAX_TSDR
    if not low <= params.tsl <= TSL_MAX:
        problems.append(("tsl", f"{params.tsl} is outside max_tsdr + 15 ({low})..{TSL_MAX}"))
    lo, hi = RETRIES_RANGE
    if not lo <= params.retries <= hi:
        problems.append(("retries", f"{params.retries} is outside {lo}..{hi}"))
    return problems
