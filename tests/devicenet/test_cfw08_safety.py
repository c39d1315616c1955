"""CFW-08 command safety (issue 32): no stale run after a reconnect (item 1), the drive's
own reaction to a lost master (item 5, P313), local control (item 6), a motor turning
counter-clockwise on 20/70 (item 8) and poll responses beyond one per poll (item 12).

Golden bytes from the seed: assembly 21 (table 6) b0 Run Fwd, b5 NetCtrl, b6 NetRef,
speed in rpm little-endian; 600 rpm = 0x0258.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from adapters.devicenet.adapter import DOUBT_CLEAN_INPUTS, DeviceNetAdapter
from adapters.devicenet.cfw08 import (
    AssemblyPair,
    In70,
    In71,
    In150,
    ProfileSettings,
    state_changes,
)
from adapters.devicenet.cfw08.profile import Cfw08Profile
from adapters.devicenet.codec.ids import PredefinedMessage
from adapters.devicenet.scanner import (
    InputData,
    IoConflict,
    NodeConfig,
    NodeDown,
    NodeUp,
    Phase,
    ScannerConfig,
)
from adapters.devicenet.scanner.events import NodeIdentity
from adapters.devicenet.sim.drive import SimDrive, SimDriveConfig
from adapters.devicenet.sim.node import SimNodeConfig
from gateway.adapter import EventKind
from gateway.config import parse
from gateway.model import DesiredCommand, Direction
from tests.devicenet.harness import Line

MAC = 5
RUN_600 = DesiredCommand(run=True, speed_rpm=600.0)
STOP = "60 00 00 00"  # 21: NetCtrl + NetRef, no run, no speed (seed table 6)
RUN_FWD_600 = "61 00 58 02"  # 21: Run Fwd + NetCtrl + NetRef, 600 rpm


def adapter_for(**drive: Any) -> DeviceNetAdapter:
    table = {
        "adapter": "devicenet",
        "drives": [{"id": "d", "device": "CFW-08", "address": MAC, "max_rpm": 1800, **drive}],
    }
    config = parse(
        {"zenoh": {"enabled": False}, "modbus": {"enabled": False}, "buses": {"dn": table}},
        "test.toml",
    )
    return DeviceNetAdapter(config.buses[0])


class FakeHub:
    """A hub that keeps whatever desired command it is given (as a hub that does not
    clear run on a comm loss would): the adapter must not rely on it."""

    def __init__(self, desired: DesiredCommand) -> None:
        self.want = desired
        self.updates: list[dict[str, Any]] = []
        self.events: list[tuple[EventKind, str]] = []

    def desired(self, drive_id: str) -> DesiredCommand:
        return self.want

    def update(self, drive_id: str, **changes: Any) -> None:
        self.updates.append(changes)

    def event(self, drive_id: str, kind: EventKind, text: str, **data: Any) -> None:
        self.events.append((kind, text))

    def set_capabilities(self, drive_id: str, caps: object) -> None:
        return None


class Outputs:
    """The scanner's side of the outputs: what the adapter set for the node."""

    def __init__(self) -> None:
        self.sent: list[str] = []
        self.nodes = {MAC: SimpleNamespace(phase=Phase.ONLINE, quiet=False)}

    def set_output(self, mac: int, data: bytes | None) -> None:
        self.sent.append("idle" if data is None else data.hex(" "))

    def quiet_inputs(self, mac: int, quiet: bool) -> None:
        self.nodes[mac].quiet = quiet


def wired(hub: FakeHub) -> tuple[DeviceNetAdapter, Outputs]:
    adapter = adapter_for()
    engine = Outputs()
    adapter.engine = engine  # type: ignore[assignment]
    adapter._hub = hub  # type: ignore[assignment]
    return adapter, engine


def configured(adapter: DeviceNetAdapter) -> None:
    """What the adapter does once the profile's on_connect succeeded (adapter._try_configure)."""
    d = adapter.drives[MAC]
    d.configured, d.problem = True, None
    if hasattr(adapter, "_disarm"):  # (issue 32: not in the code before it)
        adapter._disarm(d)
    d.input_key = d.output_key = None


# ---------------------------------------------------------------- item 1


def test_first_output_after_a_reconnect_is_a_stop_whatever_the_hub_holds() -> None:
    hub = FakeHub(RUN_600)  # a run from before the loss, still held
    adapter, engine = wired(hub)
    configured(adapter)
    adapter._refresh_outputs(1.0)
    adapter._refresh_outputs(1.1)
    assert engine.sent == [STOP]  # never the held run, however often refreshed
    hub.want = DesiredCommand(run=True, speed_rpm=600.0)  # a run given since: sent
    adapter._refresh_outputs(1.2)
    assert engine.sent[-1] == RUN_FWD_600

    # the drive is lost (power blip, cable, bus-off) and comes back, the run still held
    adapter._on_node_down(2.0, NodeDown(MAC, "no data for 0.8 s (4 x EPR)"))
    configured(adapter)
    engine.sent.clear()
    adapter._refresh_outputs(3.0)
    adapter._refresh_outputs(3.1)
    assert engine.sent == [STOP]
    hub.want = DesiredCommand(speed_rpm=600.0)  # the hub clears the run: the next is taken
    adapter._refresh_outputs(3.2)
    hub.want = RUN_600
    adapter._refresh_outputs(3.3)
    assert engine.sent[-1] == RUN_FWD_600


def test_a_run_given_right_after_the_reconnection_follows_the_first_stop() -> None:
    hub = FakeHub(DesiredCommand())
    adapter, engine = wired(hub)
    configured(adapter)
    hub.want = DesiredCommand(run=True, speed_rpm=600.0)  # given before the first output
    adapter._refresh_outputs(1.0)
    adapter._refresh_outputs(1.1)
    assert engine.sent == [STOP, RUN_FWD_600]


def test_a_jog_held_over_a_reconnect_is_not_sent_either() -> None:
    hub = FakeHub(DesiredCommand(jog=True, remote=True))
    adapter = adapter_for(assembly=100)
    engine = Outputs()
    adapter.engine, adapter._hub = engine, hub  # type: ignore[assignment]
    configured(adapter)
    adapter._refresh_outputs(1.0)
    word = bytes.fromhex(engine.sent[-1])
    assert word[0] & 0x09 == 0  # seed table 7: b0 Habilita Rampa and b3 JOG off


def test_node_up_disarms_whatever_came_before() -> None:
    hub = FakeHub(DesiredCommand())
    adapter, engine = wired(hub)
    configured(adapter)
    adapter._refresh_outputs(1.0)
    adapter._refresh_outputs(1.1)
    assert adapter.drives[MAC].armed
    hub.want = RUN_600

    class Loop:
        def create_task(self, coro: Any, name: str = "") -> None:
            coro.close()

    import asyncio

    real = asyncio.get_running_loop
    asyncio.get_running_loop = Loop  # type: ignore[assignment]
    try:
        adapter._on_node_up(2.0, NodeUp(MAC, NodeIdentity(), 0.2))
    finally:
        asyncio.get_running_loop = real
    configured(adapter)
    adapter._refresh_outputs(3.0)
    assert engine.sent[-1] == STOP


# ---------------------------------------------------------------- item 8


S20 = ProfileSettings(pair=AssemblyPair.BASIC)


def test_20_70_a_motor_turning_counter_clockwise_is_running_in_reverse() -> None:
    # seed 3.1.1: Running1 only while turning clockwise; table 5 has no Running2
    changes = state_changes(S20, In70(running1=False, speed_rpm=900).encode(), DesiredCommand())
    assert changes["running"] is True
    assert changes["direction"] is Direction.REVERSE
    assert changes["speed_rpm"] == -900.0
    stopped = state_changes(S20, In70(speed_rpm=0).encode(), DesiredCommand())
    assert stopped["running"] is False
    forward = state_changes(S20, In70(running1=True, speed_rpm=900).encode(), RUN_600)
    assert forward["direction"] is Direction.FORWARD and forward["speed_rpm"] == 900.0


# ---------------------------------------------------------------- items 5 and 6


def profile(assembly: int = 21, **params: int) -> Cfw08Profile:
    adapter = adapter_for(assembly=assembly)
    p = adapter.drives[MAC].profile
    assert isinstance(p, Cfw08Profile)
    p.params.update({f"P{n}": v for n, v in params.items()})
    return p


IN71_NET = In71(ready=True, ctrl_from_net=True, drive_state=3).encode()


@pytest.mark.parametrize(
    ("p313", "failsafe", "words"),
    [
        (0, True, "ramp disable"),
        (1, True, "general disable"),
        (2, False, "keeps the motor turning"),  # the factory value (seed 4.1.3)
        (3, False, "local mode"),
        (None, None, None),
    ],
)
def test_p313_is_the_failsafe(p313: int | None, failsafe: bool | None, words: str | None) -> None:
    p = profile()
    p.p313, p.io_timeout = p313, 0.8
    changes = p.inputs(IN71_NET, DesiredCommand())
    assert changes["failsafe"] is failsafe
    text = changes["failsafe_text"]
    if words is None:
        assert text is None
    else:
        assert text is not None and words in text and f"P313 = {p313}" in text
        assert "0.8 s" in text  # 4 x EPR: when the drive sees the master lost


def test_21_71_ctrl_from_net_clear_is_local_control() -> None:
    p = profile()
    local = In71(ready=True, ctrl_from_net=False, drive_state=3).encode()
    assert p.inputs(local, DesiredCommand())["local_control"] is True
    assert p.inputs(IN71_NET, DesiredCommand())["local_control"] is False


@pytest.mark.parametrize(
    ("remote", "p229", "p230", "local"),
    [
        (True, 0, 1, True),  # the seed's factory values: remote commands from the terminals
        (True, 0, 2, False),
        (False, 0, 2, True),  # local situation, commands from the keypad
        (False, 2, 0, False),
    ],
)
def test_100_150_situation_and_its_command_source(
    remote: bool, p229: int, p230: int, local: bool
) -> None:
    p = profile(100, **{"229": p229, "230": p230})
    data = In150(remote=remote, general_enabled=True).encode()
    assert p.inputs(data, DesiredCommand())["local_control"] is local


def test_20_70_local_control_from_the_control_supervisor() -> None:
    p = profile(20)
    p.ctrl_from_net = False  # table 16 attribute 15, read at connect and each status poll
    changes = p.inputs(In70().encode(), DesiredCommand())
    assert changes["local_control"] is True and changes["remote"] is False
    p.ctrl_from_net = True
    assert p.inputs(In70().encode(), DesiredCommand())["local_control"] is False


# ---------------------------------------------------------------- the simulator (seed 4.1.3, 4.2)


def running_sim(p710: int, params: dict[int, int] | None = None) -> SimDrive:
    sim = SimDrive(SimDriveConfig(p710=p710, p313=0, ramp_time=0.1))
    sim.params.update(params or {})
    sim.power_up()
    return sim


OUT = {0: "01 00 58 02", 1: "61 00 58 02", 2: "13 00 00 0b"}


@pytest.mark.parametrize("p710", [0, 1, 2])
def test_sim_obeys_the_network_only_when_its_commands_are_from_devicenet(p710: int) -> None:
    sim = running_sim(p710)
    sim.apply_output(bytes.fromhex(OUT[p710]))
    sim.advance(0.5)
    assert sim.motor.speed > 500
    sim.params[230] = 1  # remote commands from the terminals (seed 4.2.5)
    sim.advance(0.5)
    assert sim.motor.speed == 0.0 and not sim.network_control


def test_sim_p313_go_to_local_stops_a_20_70_drive() -> None:
    # seed 4.1.3: P313 = 3 goes to local mode; with the keypad's commands in local (P229 =
    # 0) the simulated drive stops (audit row C24: on 20/70 it kept running)
    sim = running_sim(0, {313: 3})
    sim.apply_output(bytes.fromhex(OUT[0]))
    sim.advance(0.5)
    sim.comm_loss(37)
    sim.advance(0.5)
    assert sim.motor.speed == 0.0 and not sim.network_control


def test_sim_p231_fixes_the_direction() -> None:
    sim = running_sim(0, {231: 1})  # seed 4.2.6: always counter-clockwise
    sim.apply_output(bytes.fromhex(OUT[0]))
    sim.advance(0.5)
    assert sim.motor.speed < -500
    assert not sim.input_assembly().running1  # type: ignore[union-attr]


# ---------------------------------------------------------------- item 12


def test_a_second_answer_to_one_poll_is_a_conflict_and_not_delivered() -> None:
    config = ScannerConfig(
        dupmac_timeout=0.05,
        poll_interval=0.02,
        response_timeout=0.01,
        explicit_timeout=0.05,
        allocate_timeout=0.05,
        retry_min=0.05,
        retry_max=0.4,
    )
    line = Line(
        config,
        [NodeConfig(MAC, epr=0.05)],
        [SimNodeConfig(mac=MAC, dupmac_timeout=0.05)],
        outputs={MAC: bytes.fromhex(STOP)},
    )
    line.power_on()
    line.run(2.0)
    assert line.scanner.nodes[MAC].phase is Phase.ONLINE
    line.take(InputData)
    node = line.sims[MAC]
    forged = In71(running1=True, drive_state=4, speed_rpm=1500).encode()
    line._pending.append((node, node._frame(PredefinedMessage.SLAVE_POLL_RESPONSE, forged)))
    line.run(0.05)
    conflicts = line.take(IoConflict)
    assert [(c.mac, c.data, c.count) for c in conflicts] == [(MAC, forged, 1)]
    assert forged not in [a.data for a in line.take(InputData)]
    assert line.scanner.node_diagnostics(MAC)["io_conflicts"] == 1


def test_conflicts_make_the_drive_doubtful_until_clean_inputs() -> None:
    hub = FakeHub(DesiredCommand())
    adapter, _ = wired(hub)
    configured(adapter)
    data = In71(ready=True, ctrl_from_net=True, drive_state=3).encode()
    for i in range(5):
        adapter._on_conflict(1.0 + i, IoConflict(MAC, data, i + 1))
    assert [u for u in hub.updates if "doubtful" in u and len(u) == 1] == [{"doubtful": True}]
    bus = [t for k, t in hub.events if k is EventKind.BUS]
    assert len(bus) == 1 and "MAC 5" in bus[0]  # one event, then at most one per interval
    adapter._on_conflict(20.0, IoConflict(MAC, data, 6))
    bus = [t for k, t in hub.events if k is EventKind.BUS]
    assert len(bus) == 2 and bus[1].startswith("node 5: 5 poll response(s)")
    for _ in range(DOUBT_CLEAN_INPUTS - 1):
        adapter._on_input(21.0, InputData(MAC, data))
    assert hub.updates[-1]["doubtful"] is True  # published with the readings
    adapter._on_input(21.0, InputData(MAC, data))
    assert {"doubtful": False} in hub.updates and hub.updates[-1]["doubtful"] is False
