"""What every benchmark reports: one figure per line, with its in-run reference."""

from __future__ import annotations

import argparse
import json
import os
import select
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from typing import Final


@dataclass(frozen=True)
class Figure:
    name: str
    value: float
    unit: str
    reference: float | None = None  # the same measure for the reference, in this run
    target: str | None = None  # what the issue asks, e.g. "ratio >= 0.5"
    note: str = ""

    @property
    def ratio(self) -> float | None:
        if self.reference in (None, 0):
            return None
        return self.value / self.reference

    def to_json(self) -> dict[str, object]:
        out = asdict(self)
        out["ratio"] = None if self.ratio is None else round(self.ratio, 4)
        return out

    def line(self) -> str:
        return json.dumps(self.to_json())


SLEEP: Final = 66e-6  # s: TSYN at 500 kbit/s (33 bit times), the idle time slept per exchange


def sleep_cpu(wait: float = SLEEP, count: int = 500) -> tuple[float, float]:
    """The CPU time (s) this process is charged per blocking ``select(2)`` sleep of
    ``wait`` s, and per the same call with no wait: ``(sleep, call)``.

    The sleep waits on a pipe nobody writes, as the stream driver waits on its port for an
    idle time. What the sleep costs beyond the call is the kernel's (and, in a virtual
    machine, the hypervisor's) price of going to sleep and waking, charged to the process
    whatever its code: with line timing kept, a master that does not spin sleeps once more
    per exchange than one that keeps no timing. The caller sets the timer slack it runs
    with (the stream driver sets 1 us: :func:`adapters.link.timer.precise_sleeps`)."""
    read, write = os.pipe()
    try:
        costs = []
        for timeout in (wait, 0.0):
            start = time.process_time()
            for _ in range(count):
                select.select([read], [], [], timeout)
            costs.append((time.process_time() - start) / count)
    finally:
        os.close(read)
        os.close(write)
    return costs[0], costs[1]


def first_paragraph(doc: str | None) -> str:
    """The first paragraph of a module's docstring, for its ``--help``."""
    return " ".join((doc or "").strip().split("\n\n", 1)[0].split())


class _ShowDefaults(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's default in its help, but for a flag or an unset option."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default is None or isinstance(action.default, bool):
            return action.help
        return super()._get_help_string(action)


def arg_parser(
    module: str,
    doc: str | None,
    epilog: str = "make bench (python -m bench) runs it with the defaults.",
) -> argparse.ArgumentParser:
    """The command line of ``python -m bench.<module>``: the description is the first
    paragraph of the module's docstring, every option's help shows its default (the value
    ``make bench`` runs with), and a bad option exits 2 with argparse's message before
    anything starts."""
    return argparse.ArgumentParser(
        prog=f"python -m bench.{module}",
        description=first_paragraph(doc),
        epilog=epilog,
        formatter_class=_ShowDefaults,
    )


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1 (a count of rounds, nodes, calls)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: must be 1 or more")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a number of seconds > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a finite number above 0")
    return value


def id_range(low: int, high: int, what: str) -> Callable[[str], int]:
    """An argparse type: a count or address within ``low``-``high`` (``what`` names it)."""

    def parse(text: str) -> int:
        value = positive_int(text)
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text!r}: {what} are {low}-{high}")
        return value

    return parse


def add_counts(
    parser: argparse.ArgumentParser,
    flag: str,
    parse: Callable[[str], int],
    default: Iterable[int],
    help: str,
    *,
    may_be_empty: bool = False,
) -> None:
    """An option taking one count per case (nodes, slaves); ``may_be_empty``: none at all
    skips those cases."""
    parser.add_argument(
        flag,
        type=parse,
        nargs="*" if may_be_empty else "+",
        metavar="N",
        default=list(default),
        help=help,
    )


def add_number(
    parser: argparse.ArgumentParser,
    flag: str,
    default: float,
    help: str,
) -> None:
    """An option taking one number: seconds when ``default`` is a float, else a count."""
    seconds = isinstance(default, float)
    parser.add_argument(
        flag,
        type=positive_float if seconds else positive_int,
        metavar="S" if seconds else "N",
        default=default,
        help=help,
    )


def node_counts_main(
    argv: list[str] | None,
    module: str,
    doc: str | None,
    *,
    ids: Callable[[str], int],
    counts: Iterable[int],
    what: str,
    seconds: float,
    run: Callable[[tuple[int, ...], float], list[Figure]],
) -> int:
    """The command line of a bench with one case per node count (``--nodes``, ``--seconds``):
    parse it, run, print the figures."""
    parser = arg_parser(module, doc)
    add_counts(parser, "--nodes", ids, counts, what)
    add_number(parser, "--seconds", seconds, "seconds measured per case")
    args = parser.parse_args(argv)
    print_figures(run(tuple(args.nodes), args.seconds))
    return 0


def print_figures(figures: Iterable[Figure]) -> None:
    """One JSON line per figure on stdout, as ``python -m bench`` prints them."""
    for figure in figures:
        print(figure.line(), flush=True)
