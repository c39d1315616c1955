"""A simulated slave configured from a GSD file: it judges start-up bytes as the file says.

:class:`GsdSim` wraps a device simulator (its telegram is the device's own programming, e.g.
P0922 words or the MCD 600 mode) and answers for the GSD's side of the start-up:

* Set_Prm: the Ident_Number must be the GSD's; the user data (the master's DP-V1 status
  bytes stand in for DPV1_Status_1..3) must have the length the GSD gives for the modules
  and every ExtUserPrmData value in its range. Else Prm_Fault.
* Chk_Cfg: the bytes must be a row of the GSD's modules (one for a compact station, at most
  Max_Module for a modular one) whose I/O sizes are the device's own telegram. Else
  Cfg_Fault; Get_Cfg answers the first module of the file that fits the telegram.

Everything else (data exchange, records, diagnosis) is the wrapped device's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from adapters.profibus.codec.chkcfg import decode_identifiers, total_input_bytes, total_output_bytes
from adapters.profibus.codec.gsd import (
    DPV1_STATUS_BYTES,
    Gsd,
    GsdModule,
    check_user_prm,
    match_modules,
    station_prm_len,
)

if TYPE_CHECKING:
    from adapters.profibus.codec.dp import GlobalControl
    from adapters.profibus.contract import SimDevice
    from gateway.sim import FaultInjector

SEARCH_DEPTH = 8  # modules tried in a row for Get_Cfg before the first Chk_Cfg


class GsdSim:
    """A device simulator behind a GSD file's start-up checks (see the module docstring)."""

    def __init__(self, device: SimDevice, gsd: Gsd, *, modules: tuple[str, ...] = ()) -> None:
        self.device = device
        self.gsd = gsd
        self.ident_number = gsd.ident_number
        ids = decode_identifiers(device.expected_cfg())
        self.sizes = (total_input_bytes(ids), total_output_bytes(ids))
        own = tuple(m for m in (gsd.module(name) for name in modules) if m is not None)
        # the slave's own modules (from its config), then as the last Chk_Cfg named them
        self.modules: tuple[GsdModule, ...] | None = own if own and self._fits(own) else None
        self.user_prm: bytes = b""
        self.refusal = ""  # why the last Set_Prm or Chk_Cfg was refused

    def __getattr__(self, name: str) -> Any:
        """The wrapped device's own attributes (its state, for tests and tools)."""
        return getattr(self.device, name)

    # ------------------------------------------------------------------ the device's hooks

    @property
    def dpv1(self) -> bool:
        return self.device.dpv1

    @property
    def reads_user_prm(self) -> bool:
        return self.device.reads_user_prm

    @property
    def faults(self) -> FaultInjector | None:
        return self.device.faults

    def alerts(self, ext: bytes) -> bool:
        return self.device.alerts(ext)

    @property
    def handles_clear(self) -> bool:
        return self.device.handles_clear

    def clear_mode(self, now: float, active: bool) -> None:
        self.device.clear_mode(now, active)

    def global_control(self, control: GlobalControl, now: float) -> None:
        self.device.global_control(control, now)

    def baud_detected(self, baudrate: int) -> None:
        self.device.baud_detected(baudrate)

    def write_answer_length(self, written: int) -> int:
        return self.device.write_answer_length(written)

    def exchange(self, outputs: bytes, now: float) -> bytes:
        return self.device.exchange(outputs, now)

    def comm_lost(self, now: float) -> None:
        self.device.comm_lost(now)

    def read_record(self, slot: int, index: int, length: int, now: float) -> bytes:
        return self.device.read_record(slot, index, length, now)

    def write_record(self, slot: int, index: int, data: bytes, now: float) -> None:
        self.device.write_record(slot, index, data, now)

    def ext_diag(self) -> bytes:
        return self.device.ext_diag()

    def tick(self, now: float) -> None:
        self.device.tick(now)

    def power_cycle(self, now: float) -> None:
        self.device.power_cycle(now)

    # ------------------------------------------------------------------ the GSD's checks

    def _fits(self, modules: tuple[GsdModule, ...]) -> bool:
        ins = sum(m.input_bytes for m in modules)
        outs = sum(m.output_bytes for m in modules)
        return (ins, outs) == self.sizes

    def expected_cfg(self) -> bytes:
        """Get_Cfg: the modules last accepted, else the first row of the file's modules
        that fits the telegram (a single module first), else the device's own bytes."""
        if self.modules is not None:
            return b"".join(m.config for m in self.modules)
        row = self._first_row((), 1 if not self.gsd.modular else self._most())
        if row is not None:
            return b"".join(m.config for m in row)
        return bytes(self.device.expected_cfg())

    def _most(self) -> int:
        return min(self.gsd.get("max_module") or SEARCH_DEPTH, SEARCH_DEPTH)

    def _first_row(self, row: tuple[GsdModule, ...], most: int) -> tuple[GsdModule, ...] | None:
        """Depth-first over the modules in file order, never past the telegram's sizes."""
        ins = sum(m.input_bytes for m in row)
        outs = sum(m.output_bytes for m in row)
        if row and (ins, outs) == self.sizes:
            return row
        if len(row) >= most or ins > self.sizes[0] or outs > self.sizes[1]:
            return None
        for m in self.gsd.modules:
            if not m.input_bytes and not m.output_bytes:
                continue  # an empty slot adds nothing: never a way forward
            found = self._first_row((*row, m), most)
            if found is not None:
                return found
        return None

    def check_cfg(self, cfg: bytes) -> bool:
        modules = match_modules(self.gsd, bytes(cfg))
        if modules is None:
            return self._refuse(f"{bytes(cfg).hex(' ').upper()} is no row of the GSD's modules")
        most = self.gsd.get("max_module") if self.gsd.modular else 1
        if most is not None and len(modules) > most:
            return self._refuse(f"{len(modules)} modules, Max_Module = {most}")
        if not self._fits(modules):
            return self._refuse(
                f"modules {[m.name for m in modules]} do not fit the telegram {self.sizes}"
            )
        reason = self._check_prm(modules)
        if reason is not None:
            return self._refuse(reason)
        self.modules = modules
        return self.device.check_cfg(self.device.expected_cfg())

    def _check_prm(self, modules: tuple[GsdModule, ...]) -> str | None:
        data = self.user_prm
        if self.gsd.dpv1:
            data = bytes(self.gsd.user_prm_data[:DPV1_STATUS_BYTES]).ljust(3, b"\0") + data
        return check_user_prm(self.gsd, modules, data)

    def _refuse(self, reason: str) -> bool:
        self.refusal = reason
        return False

    def set_prm(self, user_prm: bytes) -> bool:
        """Kept for the Chk_Cfg check (module blocks); the station's own part checked now."""
        self.user_prm = bytes(user_prm)
        data = self.user_prm
        if self.gsd.dpv1:
            data = bytes(self.gsd.user_prm_data[:DPV1_STATUS_BYTES]).ljust(3, b"\0") + data
        reason = check_user_prm(self.gsd, (), data[: station_prm_len(self.gsd)])
        if reason is not None:
            return self._refuse(reason)
        return bool(self.device.set_prm(self.user_prm if self.reads_user_prm else b""))
