"""``/metrics``: what the gateway held back from floods, each limit's counter.

- ``events_folded``: events held back as repeats of their drive's event before them (the
  hub's folding, gateway/eventlog.py: told once, with a count);
- per bus, from the line's diagnostics as its own loop last built them (never the line's
  live objects): the events its hand-over to the hub dropped (``events_dropped``,
  gateway/runtime/lineport.py), the CANopen EMCY frames over their node's budget
  (``emcy_dropped``, adapters/canopen/master/emcy.py), the Duplicate MAC ID requests for
  the DeviceNet scanner's own MAC left unanswered (``own_mac_claims_unanswered``,
  adapters/devicenet/scanner/ownmac.py). A line that does not give one has no sample;
- ``web_tokens_failed``: wrong command tokens on the web (gateway/web/tokens.py), each
  answered 401.

:class:`FloodCollector` sits on the web front end's registry beside the gateway's collector
(gateway/web/metrics.py) and is read only when a scrape renders.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING

from prometheus_client.core import CounterMetricFamily, Metric
from prometheus_client.registry import Collector

from gateway.frontend import RuntimeView
from gateway.web.views import bus_diagnostics

if TYPE_CHECKING:
    from gateway.web.counters import WebCounters

_NS = "drive_gateway"

FLOOD_METRICS: dict[str, str] = {
    f"{_NS}_events_folded": (
        "Events held back as repeats of their drive's event before (told once, with a count)."
    ),
    f"{_NS}_bus_events_dropped": "Events a line's hand-over to the hub dropped: too many waiting.",
    f"{_NS}_bus_emcy_dropped": "CANopen EMCY frames over their node's budget, dropped unread.",
    f"{_NS}_bus_duplicate_mac_unanswered": (
        "Duplicate MAC ID requests for the DeviceNet scanner's own MAC left unanswered."
    ),
    f"{_NS}_web_tokens_failed": "Wrong command tokens given to the web page (each refused 401).",
}
"""Each counter's name (without ``_total``) and help."""

BUS_COUNTERS: dict[str, str] = {
    f"{_NS}_bus_events_dropped": "events_dropped",
    f"{_NS}_bus_emcy_dropped": "emcy_dropped",
    f"{_NS}_bus_duplicate_mac_unanswered": "own_mac_claims_unanswered",
}
"""A per-bus counter's name -> its key in the line's diagnostics."""


def _counter(name: str, labels: list[str] | None = None) -> CounterMetricFamily:
    return CounterMetricFamily(name, FLOOD_METRICS[name], labels=labels or [])


class FloodCollector(Collector):
    """Reads the flood counters at scrape time (see the module docstring)."""

    def __init__(self, runtime: RuntimeView, web: WebCounters) -> None:
        self.runtime = runtime
        self.web = web

    def collect(self) -> Iterator[Metric]:
        folded = _counter(f"{_NS}_events_folded")
        folded.add_metric([], self.runtime.hub.events_folded)
        yield folded
        yield from self._buses()
        tokens = _counter(f"{_NS}_web_tokens_failed")
        tokens.add_metric([], self.web.refused.get("token", 0))
        yield tokens

    def describe(self) -> Iterator[Metric]:
        return iter(())  # collected at scrape time only

    def _buses(self) -> Iterator[Metric]:
        diags = bus_diagnostics(self.runtime)
        for name, key in BUS_COUNTERS.items():
            family = _counter(name, ["bus"])
            for bus, diag in diags.items():
                value = diag.get(key)
                if isinstance(value, int | float) and not isinstance(value, bool):
                    family.add_metric([bus], value)
            yield family
