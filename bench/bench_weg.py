"""The WEG profile's per-exchange work: a repeated input telegram against a full decode.

A drive at rest sends the same telegram every cycle; ``WegProfile.inputs`` then returns
its last readings again (adapters/profibus/weg/profile.py, the fast path). The figure is
the time of one ``inputs`` call on a repeated telegram, against the general decode
(``_decode_inputs``) of the same telegram measured in the same run: a CFW700, manufacturer
profile, 4 words (the plant's drives) and 6 words with current, alarm, fault and speed
mapped. Each is the best of several rounds (the machine's noise only ever slows one down).

``python -m bench weg``, or alone: ``python -m bench.bench_weg [--rounds N] [--calls N]``.
"""

from __future__ import annotations

import struct
import timeit

from adapters.profibus.weg.cfw700 import Cfw700Profile
from adapters.profibus.weg.options import WegOptions
from bench.common import Figure, arg_parser, positive_int, print_figures
from gateway.config import DriveConfig
from gateway.model import DesiredCommand, Device

ROUNDS = 5
CALLS = 5_000
CASES = {
    "4_words": (WegOptions(words=4, sync_rpm=1800.0), (0x1700, 2048, 0, 0)),
    "6_words_mapped": (
        WegOptions(words=6, words_in=(3, 48, 49, 2), rated_current_a=10, sync_rpm=1800.0),
        (0x1700, 2048, 47, 0, 0, 1200),
    ),
}


def _best_us(call: object, rounds: int, calls: int) -> float:
    return min(timeit.repeat(call, number=calls, repeat=rounds)) / calls * 1e6  # type: ignore[arg-type]


def run(rounds: int = ROUNDS, calls: int = CALLS) -> list[Figure]:
    figures = []
    for name, (options, words) in CASES.items():
        drive = DriveConfig(id="d1", bus="pb", device=Device.CFW700, address=5, options=options)
        profile = Cfw700Profile(drive)
        profile.outputs(DesiredCommand(run=True, speed_rpm=450.0), 0.0)
        data = struct.pack(f">{len(words)}H", *words)
        profile.inputs(data, 0.0)
        fast = _best_us(lambda p=profile, d=data: p.inputs(d, 0.0), rounds, calls)
        general = _best_us(lambda p=profile, d=data: p._decode_inputs(d), rounds, calls)
        figures.append(
            Figure(
                f"weg_inputs_repeated_{name}",
                round(fast, 2),
                "us",
                reference=round(general, 2),
                target="ratio < 0.2",
                note="one inputs() call on a repeated telegram; reference: the full decode",
            )
        )
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = arg_parser("bench_weg", __doc__)
    parser.add_argument(
        "--rounds", type=positive_int, default=ROUNDS, help="timeit rounds (the best counts)"
    )
    parser.add_argument("--calls", type=positive_int, default=CALLS, help="calls per round")
    args = parser.parse_args(argv)
    print_figures(run(args.rounds, args.calls))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
