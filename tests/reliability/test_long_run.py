"""What the soak run (test_soak.py) found growing with time or with the number of drives,
kept bounded, in tests quick enough for ``make test``:

- the diag key: a heartbeat publishes every drive's diagnostics; the bus's diagnostics
  behind them are made once per pass, not once per drive (a line of 64 slaves made them
  64 times per heartbeat, and the event loop could not keep up);
- the simulated slaves remembered every Global_Control (Operate comes every 50 x TSL):
  the demo's memory grew for as long as it ran.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from adapters.profibus.codec.dp import GlobalControl, build_request
from adapters.profibus.codec.fdl import RequestFc, RequestFunction
from tests.e2e.harness import PREFIX, TIMEOUT
from tests.profibus.test_sim_slave import MASTER, Master, echo_slave
from tests.reliability.demo import ADDRESSES, PROFIBUS, WEG, demo_gateway

PROFIBUS_DRIVES = (*WEG, "mcd600")


async def test_one_pass_over_the_drives_makes_the_line_diagnostics_once(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        line = gw.line(PROFIBUS)  # what the runtime asks for the bus's figures
        calls = 0
        original = line.diagnostics

        def counted() -> dict[str, Any]:
            nonlocal calls
            calls += 1
            return original()

        line.diagnostics = counted  # type: ignore[method-assign]
        gw.daemon.runtime._diag.clear()  # nothing kept from the last heartbeat (no await below)
        figures = {d: gw.daemon.runtime.drive_diagnostics(d) for d in PROFIBUS_DRIVES}
        assert calls == 1
        assert {d: f["address"] for d, f in figures.items()} == {
            d: ADDRESSES[d] for d in PROFIBUS_DRIVES
        }
        # and what SCADA gets on each drive's diag key is that drive's own
        with gw.client.subscribe(f"{PREFIX}/drives/*/diag") as diag:
            seen: dict[str, dict[str, Any]] = {}
            while len(seen) < len(PROFIBUS_DRIVES):
                body = (await diag.aget(TIMEOUT)).json()
                if body["bus"] == "profibus":
                    seen[body["id"]] = body
        assert all(seen[d]["address"] == ADDRESSES[d] for d in PROFIBUS_DRIVES)
        assert all(seen[d]["state"] == "data_exchange" for d in PROFIBUS_DRIVES)


def test_a_simulated_slave_remembers_only_the_last_global_controls() -> None:
    slave, device = echo_slave()
    Master(slave).start()
    for i in range(10_000):  # 200 s of Operate at 500 kbit/s
        control = GlobalControl(sync=i == 9_999)
        request = build_request(control, da=127, sa=MASTER, fc=RequestFc(RequestFunction.SDN_HIGH))
        slave.handle(request, float(i))
    assert 0 < len(slave.counters.global_controls) <= 256
    assert 0 < len(device.global_controls) <= 256
    assert slave.counters.global_controls[-1] == device.global_controls[-1] == control
