"""The plant benchmark's northbound load, each in its own process.

``python -m bench.plant.clients modbus --port P --units 1-188 --clients 10 --rate 10
--seconds S``: that many Modbus TCP clients (raw MBAP over asyncio streams, one connection
each) polling every unit at ``rate`` Hz: each round reads the status block (input
registers 0-20, function 4) of every unit, the requests of a round pipelined (the
transaction id tells the replies apart), the next round ``1/rate`` s after the last began
(at once when it is late). Prints one JSON line: rounds, replies, exceptions, late rounds,
the achieved polls per unit per second and the round times.

``python -m bench.plant.clients zenoh --connect tcp/127.0.0.1:P --key 'plant/drives/*/state'
--seconds S``: one Zenoh peer (endpoint given, scouting off) subscribed to every drive's
state; prints the samples counted per key as one JSON line.

Both measure over the last ``--seconds`` after ``--settle`` seconds, and only 127.0.0.1.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import struct
import threading
import time
from typing import Any

from bench.plant import pin_from_env

MBAP = struct.Struct(">HHHB")  # transaction, protocol 0, length, unit
STATUS_REGISTERS = 21  # input registers 0-20: the drive's status block (docs/modbus-map.md)


def parse_units(text: str) -> list[int]:
    units: list[int] = []
    for part in text.split(","):
        low, _, high = part.partition("-")
        units.extend(range(int(low), int(high or low) + 1))
    return units


async def _client(
    port: int, units: list[int], *, rate: float, start: float, end: float, out: dict[str, Any]
) -> None:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    tid = 0
    next_round = time.monotonic()
    try:
        while True:
            now = time.monotonic()
            if now >= end:
                return
            if now < next_round:
                await asyncio.sleep(next_round - now)
            began = time.monotonic()
            frames = []
            for unit in units:
                tid = (tid + 1) & 0xFFFF
                pdu = struct.pack(">BHH", 4, 0, STATUS_REGISTERS)
                frames.append(MBAP.pack(tid, 0, len(pdu) + 1, unit) + pdu)
            writer.write(b"".join(frames))
            replies = exceptions = 0
            for _ in units:
                header = await reader.readexactly(MBAP.size)
                _, _, length, _ = MBAP.unpack(header)
                body = await reader.readexactly(length - 1)
                if body[0] & 0x80:
                    exceptions += 1
                replies += 1
            done = time.monotonic()
            if began >= start:
                out["began"].append(began)
                out["rounds"] += 1
                out["replies"] += replies
                out["exceptions"] += exceptions
                out["round_times"].append(done - began)
            next_round += 1.0 / rate
            if done > next_round:
                if began >= start:
                    out["late_rounds"] += 1
                next_round = done
    finally:
        writer.close()


async def _modbus(args: argparse.Namespace) -> dict[str, Any]:
    units = parse_units(args.units)
    now = time.monotonic()
    start, end = now + args.settle, now + args.settle + args.seconds
    outs: list[dict[str, Any]] = [
        {
            "rounds": 0,
            "replies": 0,
            "exceptions": 0,
            "late_rounds": 0,
            "round_times": [],
            "began": [],
        }
        for _ in range(args.clients)
    ]
    await asyncio.gather(
        *(_client(args.port, units, rate=args.rate, start=start, end=end, out=out) for out in outs)
    )
    times = sorted(t for out in outs for t in out["round_times"])
    replies = sum(out["replies"] for out in outs)
    return {
        "clients": args.clients,
        "units": len(units),
        "rounds": sum(out["rounds"] for out in outs),
        "replies": replies,
        "exceptions": sum(out["exceptions"] for out in outs),
        "late_rounds": sum(out["late_rounds"] for out in outs),
        # each client's rounds per second, from the first round it began to its last
        "polls_per_unit_per_s": statistics.fmean(
            (len(out["began"]) - 1) / (out["began"][-1] - out["began"][0])
            if len(out["began"]) > 1
            else 0.0
            for out in outs
        ),
        "requests_per_s": replies / args.seconds,
        "round_ms_p50": times[len(times) // 2] * 1e3 if times else None,
        "round_ms_p99": times[int(0.99 * (len(times) - 1))] * 1e3 if times else None,
    }


def _zenoh(args: argparse.Namespace) -> dict[str, Any]:
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", json.dumps("peer"))
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("listen/endpoints", json.dumps([]))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    counts: dict[str, int] = {}
    lock = threading.Lock()
    measuring = threading.Event()

    def on_sample(sample: Any) -> None:
        if measuring.is_set():
            key = str(sample.key_expr)
            with lock:
                counts[key] = counts.get(key, 0) + 1

    session = zenoh.open(config)
    try:
        sub = session.declare_subscriber(args.key, on_sample)
        time.sleep(args.settle)
        measuring.set()
        time.sleep(args.seconds)
        measuring.clear()
        sub.undeclare()
    finally:
        session.close()
    with lock:
        total = sum(counts.values())
        return {
            "keys": len(counts),
            "samples": total,
            "samples_per_s": total / args.seconds,
            "min_per_key": min(counts.values(), default=0),
        }


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m bench.plant.clients")
    sub = parser.add_subparsers(dest="what", required=True)
    m = sub.add_parser("modbus")
    m.add_argument("--port", type=int, required=True)
    m.add_argument("--units", required=True)
    m.add_argument("--clients", type=int, default=10)
    m.add_argument("--rate", type=float, default=10.0)
    z = sub.add_parser("zenoh")
    z.add_argument("--connect", required=True)
    z.add_argument("--key", required=True)
    for p in (m, z):
        p.add_argument("--settle", type=float, default=2.0)
        p.add_argument("--seconds", type=float, required=True)
    args = parser.parse_args()
    pin_from_env()
    result = asyncio.run(_modbus(args)) if args.what == "modbus" else _zenoh(args)
    print(json.dumps(result), flush=True)
    if args.what == "zenoh":
        import os
        import sys

        sys.stdout.flush()
        os._exit(0)  # Zenoh's native threads (as drive-gateway run leaves)


if __name__ == "__main__":
    main()
