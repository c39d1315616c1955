"""The MCD 600 profile's keys in a drive's config table, and the Set_Prm user data.

Keys (all optional)::

    mode = "basic" | "extended" | "parameter"   GSD operating mode (guide 4.1)
    flc_a = 52.0            motor full load current in A: current_a = %FLC x flc_a
    motor_set = "remote_input" | "primary" | "secondary"   control word bits 2-3 (4.2)
    comm_timeout = 10       s, 0-100: communication timeout in the GSD user data (3.3);
                            0 leaves the starter running when the master is lost (not fail-safe)
    network_comms = "soft_trip_and_log" | "trip_starter" | "warn_and_log" | "log_only"
                            what parameter 6-13 Network Communications is set to on the starter
                            (2.3, 3.3; the gateway cannot read it): its reaction to a lost
                            master, published as ``failsafe`` (unset: unknown)
    request_period = 0.1    s between data requests in the round robin (4.3)
    param_timeout = 2.0     s to wait for a parameter read/write answer (4.4)
    reset_pulse = 0.2       s the reset bit stays set for one reset request
    current_x10 = false     true for MCD6-0063B and smaller (currents in A come 10x, 4.2 note)
    ident_number = 0x0600   the card's PROFIBUS Ident_Number, from its GSD file
    group = 0               Global_Control group 1-8 for Sync/Freeze (0 = none)

Simulator only (``simulate = true``; a real starter ignores them)::

    sim_params = { 4 = 1, 9 = 1 }   the simulated starter's parameters (paramtable.py)
    sim_time_scale = 1.0    the simulated power section runs this many times faster
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

from adapters.mcd600.failsafe import NETWORK_COMMS_NAMES, failsafe_warning
from adapters.mcd600.layout import Mode
from adapters.mcd600.paramtable import PARAM_DEFS, NetworkCommsAction
from adapters.mcd600.words import MotorSet

if TYPE_CHECKING:
    from gateway.config import DriveConfig
    from gateway.schema import Table

# The guide does not give the Ident_Number (it is in the GSD file, guide 3.1); this default
# is ours and the simulator uses it too. A site sets the real one with ``ident_number``.
DEFAULT_IDENT_NUMBER: Final = 0x0600
COMM_TIMEOUT_MAX: Final = 100  # guide 3.3: 0-100 s, default 10 s
SIM_TIME_SCALE_MAX: Final = 1000.0

MOTOR_SETS: Final[dict[str, MotorSet]] = {
    "remote_input": MotorSet.REMOTE_INPUT,
    "primary": MotorSet.PRIMARY,
    "secondary": MotorSet.SECONDARY,
}


@dataclass(frozen=True, slots=True)
class Mcd600Options:
    mode: Mode = Mode.BASIC
    flc_a: float | None = None
    motor_set: MotorSet = MotorSet.REMOTE_INPUT
    comm_timeout: int = 10
    network_comms: NetworkCommsAction | None = None  # 6-13 as the site states it
    request_period: float = 0.1
    param_timeout: float = 2.0
    reset_pulse: float = 0.2
    current_x10: bool = False
    ident_number: int = DEFAULT_IDENT_NUMBER
    group: int = 0
    sim_params: tuple[tuple[int, int], ...] = ()  # (number, value) for the simulator
    sim_time_scale: float = 1.0

    @property
    def current_scale(self) -> float:
        """A per count of the currents in A (requests 3, 9-11)."""
        return 0.1 if self.current_x10 else 1.0

    @property
    def group_mask(self) -> int:
        return 1 << (self.group - 1) if self.group else 0


def safety_warning(options: Mcd600Options, watchdog: float) -> str | None:
    """``check-config``'s line for a starter with these options on a line whose DP watchdog
    for it is ``watchdog`` s (0: off), or None when it stops by itself once the master is
    gone (guide 3.3; :func:`adapters.mcd600.failsafe.failsafe_warning`)."""
    return failsafe_warning(options.comm_timeout, options.network_comms, watchdog)


def user_prm_data(options: Mcd600Options) -> bytes:
    """Set_Prm user parameter data: one byte, the communication timeout in s (guide 3.3).

    It is the first byte after the seven standard Set_Prm bytes (DP-V0 layout, no DP-V1
    status bytes: the card has no DP-V1). The guide only says the GSD carries it.
    """
    return bytes((options.comm_timeout,))


def parse_user_prm(data: bytes) -> int | None:
    """The communication timeout from Set_Prm user data, or None if it is not valid."""
    if len(data) != 1 or data[0] > COMM_TIMEOUT_MAX:
        return None
    return data[0]


def parse_options(table: Table, drive: DriveConfig) -> Mcd600Options:
    """Read the profile's keys from the drive's table (unknown keys are the caller's)."""
    d = Mcd600Options()
    mode = Mode(table.string("mode", d.mode.value, choices=[m.value for m in Mode]))
    flc = table.number("flc_a", None, minimum=0.1, maximum=10000.0)
    motor_set = table.string("motor_set", "remote_input", choices=list(MOTOR_SETS))
    return Mcd600Options(
        mode=mode,
        flc_a=flc,
        motor_set=MOTOR_SETS[motor_set],
        comm_timeout=table.integer(
            "comm_timeout", d.comm_timeout, minimum=0, maximum=COMM_TIMEOUT_MAX
        ),
        network_comms=_network_comms(table),
        request_period=table.number("request_period", d.request_period, minimum=0.0, maximum=60.0),
        param_timeout=table.number("param_timeout", d.param_timeout, minimum=0.01, maximum=60.0),
        reset_pulse=table.number("reset_pulse", d.reset_pulse, minimum=0.0, maximum=5.0),
        current_x10=table.boolean("current_x10", d.current_x10),
        ident_number=table.integer("ident_number", d.ident_number, minimum=0, maximum=0xFFFF),
        group=table.integer("group", d.group, minimum=0, maximum=8),
        sim_params=_sim_params(table),
        sim_time_scale=table.number(
            "sim_time_scale", d.sim_time_scale, minimum=0.01, maximum=SIM_TIME_SCALE_MAX
        ),
    )


def _network_comms(table: Table) -> NetworkCommsAction | None:
    name = table.string("network_comms", None, choices=list(NETWORK_COMMS_NAMES))
    return None if name is None else NETWORK_COMMS_NAMES[name]


def _sim_params(table: Table) -> tuple[tuple[int, int], ...]:
    """``sim_params``: number = value pairs the simulated starter starts with, checked
    against its parameter table (a number it does not have, a value out of its range)."""
    sub = table.table("sim_params")
    out: list[tuple[int, int]] = []
    for key in map(str, sub.data):
        number = int(key) if key.isdigit() else -1
        p = PARAM_DEFS.get(number)
        if p is None or not p.writable:
            known = ", ".join(str(n) for n, q in PARAM_DEFS.items() if q.writable)
            raise sub.error(key, f"is not a settable simulated parameter ({known})")
        out.append((number, sub.integer(key, minimum=p.low, maximum=p.high)))
    return tuple(sorted(out))
