"""Automatic Device Replacement (seed 6.1) on a running DeviceNet line.

While a drive with ``adr = true`` is missing, the line is looked at, at MAC 63 (every
:data:`ADR_INTERVAL`), for a drive with its identity (the probe of
:mod:`adapters.devicenet.scanner.probe`, on the running scanner's MAC ID); one found is
re-addressed and reset, then comes up at the missing drive's MAC ID and is reprogrammed
at connect (``startup_params``). None is looked for while a configured drive holds MAC 63.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import Protocol

from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.ids import ADR_MAC
from adapters.devicenet.contract import NodeOptions
from adapters.devicenet.options import BusOptions
from adapters.devicenet.scanner import Phase, Scanner
from adapters.devicenet.scanner.probe import (
    Finished,
    LineProbe,
    NodeInfo,
    ProbeAction,
    ProbeConfig,
    Progress,
)
from gateway.adapter import EventKind, HubPort

log = logging.getLogger(__name__)

ADR_INTERVAL = 1.0  # s between two looks at MAC 63 while an adr drive is missing


class AdrDrive(Protocol):
    """A configured drive as the replacement sees it."""

    @property
    def id(self) -> str: ...

    @property
    def mac(self) -> int: ...

    @property
    def opts(self) -> NodeOptions: ...


class AdrWatch:
    """The replacement of the missing ``adr`` drives of one line (see the module
    docstring), stepped by the adapter's driver passes."""

    def __init__(
        self,
        name: str,
        options: BusOptions,
        drives: Mapping[int, AdrDrive],
        *,
        clock: Callable[[], float],
        hub: Callable[[], HubPort],
        queue: Callable[[CanFrame], None],
    ) -> None:
        """``hub``: the running adapter's hub; ``queue``: a frame for the line's next send."""
        self.name = name
        self.options = options
        self.drives = drives
        self.clock = clock
        self.hub = hub
        self.queue = queue
        self.probe: LineProbe | None = None
        """The look at MAC 63 under way."""
        self.next_look = 0.0
        """When the next look may start."""
        self._missing_since: dict[int, float] = {}
        # the drives with ``adr = true`` (none while a configured drive holds MAC 63)
        self._adr = [] if ADR_MAC in drives else [d for d in drives.values() if d.opts.adr]

    def deadline(self) -> float | None:
        return self.probe.next_deadline() if self.probe is not None else None

    def received(self, now: float, frame: CanFrame) -> None:
        if self.probe is not None:
            self._do(now, self.probe.step(now, frame))

    def tick(self, now: float, engine: Scanner) -> None:
        """Each driver pass: which ``adr`` drives are missing since when; a look at MAC 63
        started when one is missing long enough, or the one under way stepped."""
        if not self._adr:
            return  # every pass of a line without adr drives
        for d in self._replaceable(engine):
            if engine.nodes[d.mac].phase is Phase.ONLINE:
                self._missing_since.pop(d.mac, None)
            else:
                self._missing_since.setdefault(d.mac, now)
        if self.probe is None:
            if not self._missing(now) or now < self.next_look:
                return
            o = self.options
            config = ProbeConfig(
                mac=o.mac, macs=(ADR_MAC,), timeout=o.explicit_timeout, claim=False, window=1
            )
            self.probe = LineProbe(config, self._target)
        self._do(now, self.probe.step(now))

    def _replaceable(self, engine: Scanner) -> list[AdrDrive]:
        """Drives with ``adr = true`` (none while a configured drive holds MAC 63)."""
        return self._adr if engine.online else []

    def _missing(self, now: float) -> list[AdrDrive]:
        """``adr`` drives missing long enough to be replaced (not merely slow to start)."""
        after = 2 * (self.options.explicit_timeout + self.options.dupmac_timeout)
        return [
            self.drives[mac] for mac, since in self._missing_since.items() if now - since >= after
        ]

    def _target(self, info: NodeInfo) -> int | None:
        now = self.clock()
        matches = [d for d in self._missing(now) if same_identity(d.opts, info)]
        if len(matches) == 1:
            return matches[0].mac
        if len(matches) > 1:
            names = ", ".join(d.id for d in matches)
            text = (
                f"ADR: the drive at MAC {ADR_MAC} (serial {info.serial_number}) matches "
                f"several missing drives ({names}): not re-addressed"
            )
            for d in matches:
                self.hub().event(d.id, EventKind.CONFIG, text)
        return None

    def _do(self, now: float, actions: list[ProbeAction]) -> None:
        for action in actions:
            if isinstance(action, CanFrame):
                self.queue(action)
            elif isinstance(action, Finished):
                self.probe = None
                self.next_look = now + ADR_INTERVAL
            elif isinstance(action, Progress) and action.found is not None:
                self._found(action.found)

    def _found(self, info: NodeInfo) -> None:
        target = info.readdressed
        d = self.drives.get(target) if target is not None else None
        if d is None:
            if info.problem is not None:
                log.info("DeviceNet %s: ADR at MAC %d: %s", self.name, ADR_MAC, info.problem)
            return
        self._missing_since.pop(d.mac, None)
        self.hub().event(
            d.id,
            EventKind.CONFIG,
            f"ADR: a drive with the identity of {d.id} (serial {info.serial_number}) appeared "
            f"at MAC {ADR_MAC}: set to MAC {d.mac} and reset (seed 6.1); it is reprogrammed "
            "when it connects (startup_params)",
            serial_number=info.serial_number,
        )


def same_identity(opts: NodeOptions, info: NodeInfo) -> bool:
    """The node at MAC 63 shows what this drive's config (or EDS) expects of it."""
    revision_ok = opts.revision is None or (
        info.revision is not None
        and info.revision[0] == opts.revision[0]
        and info.revision[1] >= opts.revision[1]
    )
    return (
        info.vendor_id == opts.vendor_id
        and (opts.product_code is None or info.product_code == opts.product_code)
        and (not opts.product_name or info.product_name == opts.product_name)
        and (opts.product_type is None or info.product_type == opts.product_type)
        and revision_ok
    )
