"""The CFW320 on Profibus DP: its registered DpProfile (the simulated drive is in :mod:`.sim`).

Everything the model does differently is data in :data:`adapters.profibus.weg.spec.CFW320`.
"""

from __future__ import annotations

from typing import ClassVar

from adapters.profibus.weg.profile import WegProfile
from adapters.profibus.weg.spec import CFW320, ModelSpec
from gateway.model import Device


class Cfw320Profile(WegProfile):
    """DpProfile of the CFW320 (PROFILES[Device.CFW320])."""

    device: ClassVar[Device] = Device.CFW320
    spec: ClassVar[ModelSpec] = CFW320
