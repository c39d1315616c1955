"""The CFW320 on Profibus DP: its registered DpProfile (the simulated drive is in :mod:`.sim`).

Everything the model does differently is data in :data:`adapters.profibus.weg.spec.CFW320`.
"""

from __future__ import annotations

from typing import ClassVar

from gateway.model import Device

from .profile import WegProfile
from .spec import CFW320, ModelSpec


class Cfw320Profile(WegProfile):
    """DpProfile of the CFW320 (PROFILES[Device.CFW320])."""

    device: ClassVar[Device] = Device.CFW320
    spec: ClassVar[ModelSpec] = CFW320
