"""The CFW700 on Profibus DP: its registered DpProfile (the simulated drive is in :mod:`.sim`).

Everything the model does differently is data in :data:`adapters.profibus.weg.spec.CFW700`.
"""

from __future__ import annotations

from typing import ClassVar

from adapters.profibus.weg.profile import WegProfile
from adapters.profibus.weg.spec import CFW700, ModelSpec
from gateway.model import Device


class Cfw700Profile(WegProfile):
    """DpProfile of the CFW700 (PROFILES[Device.CFW700])."""

    device: ClassVar[Device] = Device.CFW700
    spec: ClassVar[ModelSpec] = CFW700
