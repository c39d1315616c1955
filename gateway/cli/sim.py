"""``drive-gateway sim BUS ...``: run simulated devices standalone (composition level).

Each adapter package provides ``add_sim(subparsers)`` in its ``cli`` module,
found through :data:`SIMULATORS`; a package not in this build is skipped.
"""

from __future__ import annotations

from typing import Any

from gateway.loader import NotLoadable, load_optional

SIMULATORS: dict[str, str] = {
    "profibus": "adapters.profibus.cli:add_sim",
    "devicenet": "adapters.devicenet.cli:add_sim",
    "canopen": "adapters.canopen.cli:add_sim",
}


def add_sim(sub: Any) -> None:
    p = sub.add_parser("sim", help="run simulated devices standalone on a port or CAN bus")
    buses = p.add_subparsers(dest="bus", metavar="BUS", required=True)
    for target in SIMULATORS.values():
        try:
            add = load_optional(target)
        except NotLoadable:
            continue
        if add is not None:
            add(buses)
