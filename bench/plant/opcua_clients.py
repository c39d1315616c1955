"""OPC UA client sessions for the plant benchmark, in a process of their own.

``python -m bench.plant.opcua_clients --endpoint opc.tcp://127.0.0.1:P/drive-gateway
--sessions 10 --interval 0.1 --settle S --seconds S``: that many asyncua client sessions
(security none, loopback), each with one subscription at ``interval`` s monitoring every
drive's SpeedRpm, CurrentA, Status and Running (the drives found by browsing
Objects/Drives). Counts the data-change notifications over the last ``--seconds`` after
``--settle`` and prints one JSON line: sessions up, monitored items, notifications per
second in all and per session, and how long the sessions took to subscribe.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import time
from typing import Any

from asyncua import Client, ua

from bench.plant import pin_from_env

NS = 2
VARIABLES = ("SpeedRpm", "CurrentA", "Status", "Running")


class Counter:
    def __init__(self) -> None:
        self.measuring = False
        self.count = 0

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        if self.measuring:
            self.count += 1


async def _session(
    endpoint: str, interval: float, counter: Counter, up: asyncio.Event, stop: asyncio.Event
) -> dict[str, Any]:
    began = time.monotonic()
    async with Client(endpoint, timeout=60) as client:
        drives = await client.nodes.objects.get_child([f"{NS}:Drives"])
        ids = [str(n.nodeid.Identifier) for n in await drives.get_children()]
        sub = await client.create_subscription(interval * 1000, counter)
        nodes = [client.get_node(ua.NodeId(f"{d}.{v}", NS)) for d in ids for v in VARIABLES]
        await sub.subscribe_data_change(nodes, queuesize=1)
        took = time.monotonic() - began
        up.set()
        await stop.wait()
        return {"items": len(nodes), "subscribe_s": took}


async def _run(args: argparse.Namespace) -> dict[str, Any]:
    counters = [Counter() for _ in range(args.sessions)]
    stop = asyncio.Event()
    ups = [asyncio.Event() for _ in range(args.sessions)]
    tasks = [
        asyncio.create_task(_session(args.endpoint, args.interval, c, up, stop))
        for c, up in zip(counters, ups, strict=True)
    ]
    await asyncio.sleep(args.settle)
    for c in counters:
        c.measuring = True
    await asyncio.sleep(args.seconds)
    for c in counters:
        c.measuring = False
    stop.set()
    results = await asyncio.gather(*tasks, return_exceptions=True)
    done = [r for r in results if isinstance(r, dict)]
    total = sum(c.count for c in counters)
    return {
        "sessions": len(done),
        "up_before_window": sum(1 for up in ups if up.is_set()),
        "items": sum(r["items"] for r in done),
        "notifications_per_s": total / args.seconds,
        "per_session_per_s": [round(c.count / args.seconds, 1) for c in counters],
        "subscribe_s_max": max((r["subscribe_s"] for r in done), default=None),
        "errors": [repr(r) for r in results if not isinstance(r, dict)][:3],
    }


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.plant.opcua_clients")
    parser.add_argument("--endpoint", required=True)
    parser.add_argument("--sessions", type=int, default=10)
    parser.add_argument("--interval", type=float, default=0.1)
    parser.add_argument("--settle", type=float, default=2.0)
    parser.add_argument("--seconds", type=float, required=True)
    args = parser.parse_args()
    pin_from_env()
    print(json.dumps(asyncio.run(_run(args))), flush=True)


if __name__ == "__main__":
    main()
