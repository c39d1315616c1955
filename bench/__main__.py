"""``make bench``: run every benchmark, print JSON lines and a table, write bench/results.json."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import pkgutil
import sys
import time
from pathlib import Path

from bench.common import Figure

HERE = Path(__file__).resolve().parent


def discover(only: list[str]) -> list[str]:
    names = sorted(m.name for m in pkgutil.iter_modules([str(HERE)]) if m.name.startswith("bench_"))
    return [n for n in names if not only or any(o in n for o in only)]


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m bench")
    parser.add_argument(
        "only", nargs="*", help="run only benchmarks whose module name contains this"
    )
    parser.add_argument(
        "--short",
        action="store_true",
        help="shorter measuring windows where a benchmark has them (bench_plant: 8 s, not 30 s)",
    )
    args = parser.parse_args()
    if args.short:
        os.environ["BENCH_SHORT"] = "1"
    figures: list[Figure] = []
    for name in discover(args.only):
        module = importlib.import_module(f"bench.{name}")
        started = time.monotonic()
        for fig in module.run():
            print(fig.line(), flush=True)
            figures.append(fig)
        print(f"# {name}: {time.monotonic() - started:.1f} s", file=sys.stderr)
    (HERE / "results.json").write_text(json.dumps([f.to_json() for f in figures], indent=2) + "\n")
    print(f"\n{'figure':<48} {'value':>12} {'unit':<10} {'ratio':>7}  target", file=sys.stderr)
    for f in figures:
        ratio = "" if f.ratio is None else f"{f.ratio:.3f}"
        print(
            f"{f.name:<48} {f.value:>12.4g} {f.unit:<10} {ratio:>7}  {f.target or ''}",
            file=sys.stderr,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
