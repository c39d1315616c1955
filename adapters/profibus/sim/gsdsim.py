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

from typing import Any

from adapters.profibus.cfg import decode_identifiers, total_input_bytes, total_output_bytes
from adapters.profibus.gsd import (
    DPV1_STATUS_BYTES,
    Gsd,
    GsdModule,
    check_user_prm,
    match_modules,
    station_prm_len,
)


class GsdSim:
    """A device simulator behind a GSD file's start-up checks (see the module docstring)."""

    def __init__(self, device: Any, gsd: Gsd, *, forward_prm: bool = False) -> None:
        self.device = device
        self.gsd = gsd
        self.ident_number = gsd.ident_number
        self.forward_prm = forward_prm  # the device reads the user data itself (MCD 600)
        ids = decode_identifiers(device.expected_cfg())
        self.sizes = (total_input_bytes(ids), total_output_bytes(ids))
        self.modules: tuple[GsdModule, ...] | None = None  # as the last Chk_Cfg named them
        self.user_prm: bytes = b""
        self.refusal = ""  # why the last Set_Prm or Chk_Cfg was refused

    def __getattr__(self, name: str) -> Any:
        return getattr(self.device, name)

    def _fits(self, modules: tuple[GsdModule, ...]) -> bool:
        ins = sum(m.input_bytes for m in modules)
        outs = sum(m.output_bytes for m in modules)
        return (ins, outs) == self.sizes

    def expected_cfg(self) -> bytes:
        for m in self.gsd.modules:
            if self._fits((m,)):
                return m.config
        return bytes(self.device.expected_cfg())

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
        check = getattr(self.device, "check_cfg", None)
        return bool(check(self.device.expected_cfg())) if callable(check) else True

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
        return bool(self.device.set_prm(self.user_prm if self.forward_prm else b""))
