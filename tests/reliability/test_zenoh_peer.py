"""A Zenoh peer going away and coming back, through the daemon with the demo's drives.

Two directions: the peer the gateway connects to (``zenoh.connect``: a router or the SCADA
listening) goes away and comes back, and a SCADA connected to the gateway's own endpoint
(``zenoh.listen``) leaves and joins again. The gateway keeps running through both, and
the command watchdog stops the drive whose controlling client went silent.
"""

from __future__ import annotations

import asyncio
import contextlib
from pathlib import Path

from gateway.model import Source
from tests.e2e.harness import PREFIX, TIMEOUT
from tests.reliability.demo import DRIVES, Events, at_speed, demo_gateway, stopped
from tests.zenoh.client import Client

WATCHDOG = 0.5  # s, cfw11's command_timeout


async def keep_alive(client: Client, drive: str) -> None:
    """What a SCADA in control does: refresh its command well within command_timeout."""
    while True:
        client.put(f"{PREFIX}/drives/{drive}/command", {})
        await asyncio.sleep(WATCHDOG / 5)


async def live_drives(client: Client) -> set[str]:
    """The drive tokens the client sees (liveliness history), once all have arrived."""
    with client.liveliness(f"{PREFIX}/drives/*") as live:
        seen: set[str] = set()
        while seen != set(DRIVES):
            got = await live.aget(TIMEOUT)
            if got.put:
                seen.add(got.key.rsplit("/", 1)[-1])
    return seen


async def test_the_peer_the_gateway_connects_to_goes_and_comes_back(tmp_path: Path) -> None:
    drives = {"cfw11": {"command_timeout": WATCHDOG}}
    async with demo_gateway(tmp_path, drives) as gw:
        hub = gw.daemon.hub
        loop = asyncio.get_running_loop()
        endpoint = gw.daemon.config.zenoh.connect[0]
        await gw.command("cfw11", {"run": True, "speed_rpm": 900})
        await gw.command("cfw700", {"run": True, "speed_rpm": 900})
        refresher = asyncio.create_task(keep_alive(gw.client, "cfw11"))
        try:
            await gw.wait_for("cfw11", at_speed(900.0))
            await gw.wait_for("cfw700", at_speed(900.0))
            with Events(gw) as events:
                refresher.cancel()
                gw.client.close()  # the peer's process ends
                # the controlling client is silent: the watchdog's ramp stop, once
                await events.text("cfw11", f"no command from zenoh anonymous for {WATCHDOG:g} s")
                await gw.wait_for("cfw11", stopped)
                assert hub.desired("cfw11").source is Source.GATEWAY
                # a drive without a watchdog keeps its last command (its config's choice)
                assert at_speed(900.0)(hub.state("cfw700"))
                back = Client(endpoint, loop, listen=True)  # the peer is back
                try:
                    assert await live_drives(back) == set(DRIVES)
                    state = (await back.aone(gw.state_key("cfw11"))).json()
                    assert (state["running"], state["control_source"]) == (False, "gateway")
                    # the returning client's first command is a change of source: no restart
                    reply = await back.aone(f"{PREFIX}/drives/cfw11/command", {"speed_rpm": 600})
                    assert reply.json() == {"accepted": True}
                    assert not hub.desired("cfw11").run
                    reply = await back.aone(f"{PREFIX}/drives/cfw11/command", {"run": True})
                    assert reply.json() == {"accepted": True}
                    await gw.wait_for("cfw11", at_speed(600.0))
                finally:
                    back.close()
                watchdog_events = [t for t in events.texts("cfw11") if "no command from" in t]
                assert len(watchdog_events) == 1  # applied once, not every tick
            assert gw.daemon.runtime.restarts.get("zenoh front end", 0) == 0
        finally:
            refresher.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await refresher


async def test_a_scada_on_the_gateway_endpoint_leaves_and_joins_again(tmp_path: Path) -> None:
    async with demo_gateway(tmp_path) as gw:
        loop = asyncio.get_running_loop()
        endpoint = gw.daemon.config.zenoh.listen[0]
        await gw.command("cfw08", {"run": True, "speed_rpm": 600})
        await gw.wait_for("cfw08", at_speed(600.0))
        for _ in range(2):  # joins, leaves; joins again
            scada = Client(endpoint, loop)
            try:
                assert await live_drives(scada) == set(DRIVES)
                with scada.subscribe(gw.state_key("cfw08")) as states:
                    got = await states.aget(TIMEOUT)
                assert (got.json()["running"], got.json()["speed_rpm"]) == (True, 600.0)
                health = (await scada.aone(f"{PREFIX}/gateway/health")).json()
                assert health["online"] == len(DRIVES)
            finally:
                scada.close()
        # nothing of the drives noticed the SCADA coming and going
        assert at_speed(600.0)(gw.daemon.hub.state("cfw08"))
        assert gw.daemon.runtime.restarts.get("zenoh front end", 0) == 0
