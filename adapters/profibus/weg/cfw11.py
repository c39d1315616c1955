"""The CFW-11 on Profibus DP: its registered DpProfile (the simulated drive is in :mod:`.sim`).

Everything the model does differently is data in :data:`adapters.profibus.weg.spec.CFW11`.
"""

from __future__ import annotations

from typing import ClassVar

from adapters.profibus.weg.profile import WegProfile
from adapters.profibus.weg.spec import CFW11, ModelSpec
from gateway.model import Device


class Cfw11Profile(WegProfile):
    """DpProfile of the CFW-11 (PROFILES[Device.CFW11])."""

    device: ClassVar[Device] = Device.CFW11
    spec: ClassVar[ModelSpec] = CFW11
