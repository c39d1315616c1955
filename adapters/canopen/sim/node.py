"""A simulated CiA 402 drive on CANopen: the canopen library's LocalNode around the
drive model (:mod:`adapters.canopen.sim.drive`).

The library gives the object dictionary (the EDS), the SDO server (expedited and
segmented), the PDO maps, the NMT slave with its heartbeat producer and the EMCY
producer. This module adds what a device needs besides (CiA 301):

- NMT: reset node / reset communication restore the OD and send the boot-up, then
  pre-operational (the library's slave stays in "initialising" on a reset); SDO is
  served in pre-operational and operational, PDO only in operational;
- SDO writes checked against the EDS (limits -> 0x06090031/0x06090032, unsupported
  values -> 0x06090030) and PDO mapping entries refused with 0x06040041 for an object
  that is not mappable (or not writable in an RPDO), 0x06040042 past 64 bits;
- PDO: the maps are re-read after every write to 0x1400-0x1BFF; RPDOs with
  transmission type 0-240 act on the next SYNC, 254/255 at once; TPDOs go out on the
  n-th SYNC (1-240), or on change (inhibit time 0x18xx:3) and on the event timer
  (0x18xx:5) for 254/255;
- lost communication: the heartbeat consumer 0x1016:1 (the master's node id and
  time) and the RPDO event timer 0x14xx:5 (deadline monitoring), each armed by the
  first frame it watches; on a timeout the 0x6007 reaction of the drive model;
- fault injection: a fault code, the keypad reset, power off/on, silence (a pulled
  cable: nothing in, nothing out), SDO refused (no answer) or answered late.

Threads: the network's notifier thread calls :meth:`SimNode.on_frame`, the runner's
loop calls :meth:`SimNode.step`; both take the node's lock, so the OD, the drive and
the timers change under one lock. Periodic frames (the heartbeat) are sent by
:meth:`step` on the node's clock, never by python-can's own threads.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import can
import canopen
import canopen.network
from canopen.objectdictionary import ODArray, ODVariable
from canopen.pdo.base import PdoBase, PdoMap
from canopen.sdo.exceptions import SdoAbortedError

from adapters.canopen.codec import cia402
from adapters.canopen.codec.codes import (
    ABORT_NO_OBJECT,
    ABORT_NO_SUBINDEX,
    ABORT_NOT_MAPPABLE,
    ABORT_PDO_LENGTH,
    ABORT_RANGE,
    ABORT_TOO_HIGH,
    ABORT_TOO_LOW,
)
from adapters.canopen.codec.frames import (
    COB_NMT,
    COB_SYNC,
    HEARTBEAT_BASE,
    NmtCommand,
    NmtState,
    sdo_rx_id,
)
from adapters.canopen.codec.od import parse as parse_od
from adapters.canopen.errors import EdsError
from adapters.canopen.options import read_eds
from adapters.canopen.sim.drive import Cia402Drive, CommLoss, DriveConfig, Emcy, Mode
from gateway.config import shipped_file
from gateway.errors import GatewayError
from gateway.sim import FaultInjector

log = logging.getLogger(__name__)

DEFAULT_EDS = shipped_file("eds/cia402-drive.eds")
PDO_COUNT = 4  # CiA 301: RPDO/TPDO 1-4 of the predefined connection set
MAX_PDO_BITS = 64
EPSILON = 1e-9  # s: float noise in the node's own timers (0.1 + 0.1 + 0.1 > 0.3)
SUPPORTED_VALUES: dict[int, frozenset[int]] = {
    # option codes and modes this drive implements (CiA 402-2 §6.3, §6.4)
    cia402.QUICK_STOP_OPTION: frozenset({0, 1, 2, 5, 6}),
    cia402.ABORT_CONNECTION_OPTION: frozenset(cia402.ABORT_CONNECTION_OPTIONS),
    cia402.MODES_OF_OPERATION: frozenset({cia402.MODE_VELOCITY, cia402.MODE_PROFILE_VELOCITY}),
    0x605B: frozenset({0, 1}),
    0x605C: frozenset({0, 1}),
    0x605E: frozenset({0, 1, 2}),
}
RPDO_TYPES = frozenset(range(241)) | {254, 255}  # CiA 301 §7.5.2.35
TPDO_TYPES = frozenset(range(241)) | {254, 255}  # 252/253 (RTR only) not supported


class EdsUnreadable(GatewayError, ValueError):
    """A simulated node's EDS that the canopen library cannot read (names the file)."""


def load_od(path: Path, node_id: int | None = None) -> canopen.ObjectDictionary:
    """A fresh object dictionary of an EDS, read and checked as the gateway's options do
    (a regular file of at most 4 MiB, its values in their ranges), or
    :class:`EdsUnreadable` naming the file."""
    try:
        return parse_od(str(path), read_eds(path), node_id)
    except EdsError as exc:
        detail = f"{exc.key}: {exc.reason}" if exc.key else exc.reason
        raise EdsUnreadable(f"{path}: not a readable EDS ({detail})") from None


class BootState(Enum):
    """Where a node goes after its boot-up: pre-operational (CiA 301) or straight to
    operational (a self-starting node, which the master may have to reset)."""

    PRE_OPERATIONAL = "pre_operational"
    OPERATIONAL = "operational"


@dataclass(frozen=True, slots=True)
class SimNodeConfig:
    node_id: int
    eds: Path = DEFAULT_EDS
    max_rpm: float = 1800.0
    ramp_time: float = 5.0  # s, 0 -> max_rpm (0x6048/0x6049 and 0x6083/0x6084 at boot)
    boot_state: BootState = BootState.PRE_OPERATIONAL
    heartbeat_ms: int | None = None  # 0x1017 at boot; None: the EDS default
    abort_connection_option: int | None = None  # 0x6007 at boot; None: the EDS default
    quick_stop_time: float = 0.5
    rated_current: float = 10.0

    def __post_init__(self) -> None:
        if not 1 <= self.node_id <= 127:
            raise ValueError(f"simulated CANopen node id {self.node_id} is not 1-127")


@dataclass
class Injection:
    """What a test asks the node to suffer besides the shared :class:`FaultInjector`
    (whose ``delay`` makes SDO answers late and ``drop_rate`` loses frames sent)."""

    silent: bool = False  # a pulled cable: no frame in, no frame out
    refuse_sdo: bool = False  # SDO requests go unanswered (the client times out)


class _Periodic(canopen.network.PeriodicMessageTask):
    """A periodic frame (the heartbeat) sent by the node's :meth:`SimNode.step`."""

    def __init__(self, node: SimNode, can_id: int, data: bytes, period: float) -> None:
        # no python-can cyclic task: the node's clock sends it
        self.node = node
        self.can_id = can_id
        self.data = bytes(data)
        self.period = period
        self.due = node.now + period

    def stop(self) -> None:
        self.node.periodic.pop(self.can_id, None)

    def update(self, data: bytes) -> None:
        self.data = bytes(data)


class _Port(canopen.Network):
    """The node's view of the bus: the LocalNode sends and subscribes here; frames out
    go to the shared network unless the node is off or silent."""

    def __init__(self, node: SimNode, real: canopen.Network) -> None:
        super().__init__()
        self.node = node
        self.real = real

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        node = self.node
        if node.powered and not node.injection.silent and not node.faults.drop():
            try:
                self.real.send_message(can_id, data, remote)
            except can.CanError as exc:
                self.node.send_failures += 1
                log.debug("node %d: send failed: %s", self.node.node_id, exc)
            else:
                self.node.sent += 1

    def send_periodic(
        self, can_id: int, data: bytes, period: float, remote: bool = False
    ) -> canopen.network.PeriodicMessageTask:
        task = _Periodic(self.node, can_id, data, period)
        self.node.periodic[can_id] = task
        return task


@dataclass
class _TpdoTimer:
    sync_count: int = 0
    last_sent: float | None = None
    last_data: bytes | None = None
    changed_pending: bool = False


@dataclass
class _Watch:
    """A deadline monitor: armed by the first frame, fires once per silence."""

    timeout: float = 0.0
    last: float | None = None
    fired: bool = False

    def seen(self, now: float) -> None:
        self.last = now
        self.fired = False

    def expired(self, now: float) -> bool:
        if self.timeout <= 0 or self.last is None or self.fired:
            return False
        if now - self.last > self.timeout + EPSILON:
            self.fired = True
            return True
        return False

    def deadline(self) -> float | None:
        if self.timeout <= 0 or self.last is None or self.fired:
            return None
        return self.last + self.timeout


@dataclass
class _Delayed:
    due: float
    data: bytes = field(default=b"")


class SimNode:
    """One simulated CiA 402 drive (see the module docstring)."""

    def __init__(
        self,
        config: SimNodeConfig,
        network: canopen.Network,
        *,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config
        self.node_id = config.node_id
        self.clock = clock
        self.lock = threading.RLock()
        self.network = network
        self.injection = Injection()
        self.faults = FaultInjector()
        self.powered = False
        self.now = clock()
        self.sent = 0
        self.received = 0
        self.send_failures = 0
        self.periodic: dict[int, _Periodic] = {}
        self.od = load_od(config.eds, config.node_id)
        self.local: canopen.LocalNode
        self.drive = self._new_drive()
        self._port = _Port(self, network)
        self._tpdo: dict[int, _TpdoTimer] = {}
        self._rpdo_watch: dict[int, _Watch] = {}
        self._rpdo_pending: dict[int, bytes] = {}
        self._hb_watch = _Watch()
        self._hb_node = 0
        self._sdo_queue: list[_Delayed] = []
        self._pdo_dirty = False
        self.on_routes_changed: Callable[[], None] = _nothing
        """Called when the COB-IDs the node listens to may have changed (the runner's
        routing table)."""
        self._new_local()

    # ------------------------------------------------------------ construction

    def _new_drive(self) -> Cia402Drive:
        c = self.config
        return Cia402Drive(
            DriveConfig(
                max_rpm=c.max_rpm,
                ramp_time=c.ramp_time,
                quick_stop_time=c.quick_stop_time,
                rated_current=c.rated_current,
            ),
            now=self.now,
        )

    def _new_local(self) -> None:
        """A fresh LocalNode (the OD at its EDS defaults) on the node's port."""
        local = canopen.LocalNode(self.node_id, self.od)
        lib: Any = local  # the library leaves these untyped
        lib.add_read_callback(self._on_read)
        lib.add_write_callback(self._on_write)
        self._port.subscribers.clear()  # a previous LocalNode's subscriptions
        local.associate_network(self._port)
        self._port.unsubscribe(COB_NMT, local.nmt.on_command)  # NMT is ours (_on_nmt)
        self._port.subscribe(COB_NMT, self._on_nmt)
        for pdo_map in _maps(local.rpdo).values():
            pdo_map.add_callback(self._on_rpdo)
        self.local = local

    @property
    def _lib_nmt(self) -> Any:
        return self.local.nmt  # its heartbeat calls are untyped

    def _lib_find(self, index: int, subindex: int) -> ODVariable:
        """The OD variable, or the library's SDO abort (0x06020000 / 0x06090011)."""
        lib: Any = self.local
        var: ODVariable = lib._find_object(index, subindex)
        return var

    @property
    def nmt_state(self) -> NmtState:
        state = self.local.nmt._state  # the slave's state byte (the heartbeat's)
        return NmtState(state) if state in NmtState._value2member_map_ else NmtState.BOOTUP

    # ------------------------------------------------------------ power, boot

    def power_on(self) -> None:
        with self.lock:
            self.now = self.clock()
            self.powered = True
            self._boot(reset_application=True)

    def power_off(self) -> None:
        with self.lock:
            self.powered = False
            self._lib_nmt.stop_heartbeat()
            self.periodic.clear()
            self.drive.motor.coast()

    def power_cycle(self) -> None:
        self.power_off()
        self.power_on()

    def _boot(self, *, reset_application: bool) -> None:
        """NMT initialisation (CiA 301 §7.3.2.2.1): the OD back to its defaults (the
        communication area only on a communication reset), boot-up, pre-operational."""
        self._lib_nmt.stop_heartbeat()
        self.periodic.clear()
        if reset_application:
            self.drive = self._new_drive()
            self._new_local()
            self._configure_boot_values()
        else:
            store = self.local.data_store
            for index in [i for i in store if 0x1000 <= i < 0x2000]:
                del store[index]
            if self.config.heartbeat_ms is not None:
                self._store(0x1017, 0, self.config.heartbeat_ms)
        self._tpdo.clear()
        self._rpdo_watch.clear()
        self._rpdo_pending.clear()
        self._sdo_queue.clear()
        self._hb_watch = _Watch()
        self._configure_consumer()
        self._reload_pdos()
        self.local.nmt.send_command(NmtCommand.RESET_NODE)  # state 0: sends the boot-up
        self.local.nmt.send_command(NmtCommand.ENTER_PRE_OPERATIONAL)  # starts 0x1017
        if self.config.boot_state is BootState.OPERATIONAL:
            self.local.nmt.send_command(NmtCommand.START)

    def _configure_boot_values(self) -> None:
        c, d = self.config, self.drive
        if c.heartbeat_ms is not None:
            self._store(0x1017, 0, c.heartbeat_ms)
        if c.abort_connection_option is not None:
            self._store(cia402.ABORT_CONNECTION_OPTION, 0, c.abort_connection_option)
        self._store(0x6046, 2, d.vl_max)
        self._store(0x6048, 1, d.vl_accel[0])
        self._store(0x6048, 2, d.vl_accel[1])
        self._store(0x6049, 1, d.vl_decel[0])
        self._store(0x6049, 2, d.vl_decel[1])
        self._store(0x6083, 0, d.profile_accel)
        self._store(0x6084, 0, d.profile_decel)
        self._store(0x6075, 0, d.rated_current_ma)
        self._store(0x2000, 4, round(c.max_rpm))
        # the drive model takes every input object's value, EDS default or set above
        for (index, subindex), _apply in _INPUTS.items():
            if not self._has(index, subindex):
                continue
            value = self._value(index, subindex)
            _apply(self.drive, value)

    def _has(self, index: int, subindex: int) -> bool:
        try:
            self._lib_find(index, subindex)
        except SdoAbortedError:
            return False
        return True

    def _store(self, index: int, subindex: int, value: int) -> None:
        if not self._has(index, subindex):
            return
        var = self._lib_find(index, subindex)
        self.local.data_store.setdefault(index, {})[subindex] = var.encode_raw(value)

    def _value(self, index: int, subindex: int) -> int:
        var = self._lib_find(index, subindex)
        raw = var.decode_raw(self.local.get_data(index, subindex))
        return int(raw)

    # ------------------------------------------------------------ fault injection

    def inject_fault(self, code: int) -> None:
        """A drive fault: 0x603F = ``code``, 0x1001 from it, an EMCY, the 0x605E reaction."""
        with self.lock:
            self._emcy(self.drive.inject_fault(self._tick(), code))

    def keypad_reset(self) -> None:
        """The reset key on the drive's own panel."""
        with self.lock:
            self._emcy(self.drive.keypad_reset(self._tick()))

    def silence(self, silent: bool = True) -> None:
        """Pull (True) or plug back (False) the node's cable."""
        with self.lock:
            self.injection.silent = silent

    def refuse_sdo(self, refuse: bool = True) -> None:
        with self.lock:
            self.injection.refuse_sdo = refuse

    def delay_sdo(self, delay: float) -> None:
        with self.lock:
            self.faults.delay = max(0.0, delay)

    def drop_frames(self, rate: float, seed: int = 0) -> None:
        """Lose this share of the frames the node sends (deterministic for a seed)."""
        with self.lock:
            self.faults = FaultInjector(
                seed=seed, drop_rate=max(0.0, min(rate, 1.0)), delay=self.faults.delay
            )

    def _tick(self) -> float:
        self.now = max(self.now, self.clock())
        return self.now

    # ------------------------------------------------------------ frames in

    def on_frame(self, can_id: int, data: bytes) -> None:
        """A frame from the bus (the notifier thread)."""
        with self.lock:
            if not self.powered or self.injection.silent:
                return
            now = self._tick()
            self.received += 1
            self._dispatch(now, can_id, bytes(data))
            if self._pdo_dirty:
                self._reload_pdos()

    def wants(self, can_id: int) -> bool:
        """Whether a frame with this COB-ID is for this node: NMT, SYNC, heartbeats (a
        consumer watches them), and what the LocalNode subscribed (SDO, its PDOs)."""
        return (
            can_id in (COB_NMT, COB_SYNC)
            or can_id & ~0x7F == HEARTBEAT_BASE
            or can_id in self._port.subscribers
        )

    def _dispatch(self, now: float, can_id: int, data: bytes) -> None:
        state = self.nmt_state
        if can_id == COB_NMT:
            self._port.notify(can_id, bytearray(data), now)
            return
        if can_id & ~0x7F == HEARTBEAT_BASE:
            if self._hb_node and can_id == HEARTBEAT_BASE + self._hb_node:
                self._hb_watch.seen(now)
            return
        if state is NmtState.STOPPED:
            return
        if can_id == COB_SYNC:
            if state is NmtState.OPERATIONAL:
                self._on_sync(now)
            return
        if can_id == sdo_rx_id(self.node_id):
            if self.injection.refuse_sdo:
                return
            if self.faults.delay > 0:
                self._sdo_queue.append(_Delayed(now + self.faults.delay, data))
                return
        elif state is not NmtState.OPERATIONAL:
            return  # PDOs only in operational
        self._port.notify(can_id, bytearray(data), now)

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """NMT module control (CiA 301 §7.2.8.3.1), addressed to this node or to all."""
        if len(data) < 2 or data[1] not in (0, self.node_id):
            return
        try:
            command = NmtCommand(data[0])
        except ValueError:
            return
        if command is NmtCommand.RESET_NODE:
            self._boot(reset_application=True)
        elif command is NmtCommand.RESET_COMMUNICATION:
            self._boot(reset_application=False)
        else:
            self.local.nmt.send_command(command)

    def _on_rpdo(self, pdo_map: PdoMap) -> None:
        if not pdo_map.enabled:
            return
        number = _map_number(pdo_map)
        watch = self._rpdo_watch.get(number)
        if watch is not None:
            watch.seen(self.now)
        if pdo_map.trans_type is not None and pdo_map.trans_type <= 240:
            self._rpdo_pending[number] = bytes(pdo_map.data)  # acts on the next SYNC
            return
        self._apply_rpdo(pdo_map)

    def _apply_rpdo(self, pdo_map: PdoMap) -> None:
        for var in pdo_map:
            try:
                self.local.set_data(var.index, var.subindex, var.get_data())
            except SdoAbortedError as exc:
                log.debug("node %d: RPDO value 0x%04X refused: %s", self.node_id, var.index, exc)

    def _on_sync(self, now: float) -> None:
        for number, data in list(self._rpdo_pending.items()):
            del self._rpdo_pending[number]
            pdo_map = _maps(self.local.rpdo)[number]
            pdo_map.data = bytearray(data)
            self._apply_rpdo(pdo_map)
        self.drive.step(now)
        for number, pdo_map in _maps(self.local.tpdo).items():
            tt = pdo_map.trans_type
            if not pdo_map.enabled or tt is None or tt > 240:
                continue
            timer = self._tpdo.setdefault(number, _TpdoTimer())
            data = _tpdo_data(self.local, pdo_map)
            if tt == 0:  # acyclic synchronous: on SYNC after a change
                if data != timer.last_data:
                    self._send_tpdo(now, pdo_map, timer, data)
                continue
            timer.sync_count += 1
            if timer.sync_count >= tt:
                timer.sync_count = 0
                self._send_tpdo(now, pdo_map, timer, data)

    # ------------------------------------------------------------ OD access

    def _on_read(self, *, index: int, subindex: int, od: ODVariable) -> int | None:
        _check_sub(self.od, index, subindex)
        get = _LIVE.get((index, subindex))
        return None if get is None else get(self.drive)

    def _on_write(self, *, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        """Checks a write before the library stores it (raising an SDO abort refuses it)
        and hands drive inputs to the drive model."""
        _check_sub(self.od, index, subindex)
        value = od.decode_raw(data)
        if isinstance(value, int) and not isinstance(value, bool):
            if od.min is not None and value < od.min:
                raise SdoAbortedError(ABORT_TOO_LOW)
            if od.max is not None and value > od.max:
                raise SdoAbortedError(ABORT_TOO_HIGH)
            allowed = SUPPORTED_VALUES.get(index)
            if allowed is not None and value not in allowed:
                raise SdoAbortedError(ABORT_RANGE)
        if 0x1400 <= index < 0x1C00:
            self._check_pdo_write(index, subindex, value)
            self._pdo_dirty = True
        elif index == 0x1016 and subindex == 1:
            self._configure_consumer(int(value))
        apply = _INPUTS.get((index, subindex))
        if apply is not None:
            now = self._tick()
            self.drive.step(now)
            self._emcy(apply(self.drive, int(value)) or [])
            self.drive.set_reference_inputs(now)

    def _check_pdo_write(self, index: int, subindex: int, value: Any) -> None:
        rx = index < 0x1800
        area = index & 0xFE00
        if area in (0x1400, 0x1800) and subindex == 2:
            if value not in (RPDO_TYPES if rx else TPDO_TYPES):
                raise SdoAbortedError(ABORT_RANGE)
            return
        if area not in (0x1600, 0x1A00):
            return
        if subindex == 0:
            bits = 0
            for sub in range(1, int(value) + 1):
                entry = self._value(index, sub) if self._has(index, sub) else 0
                bits += entry & 0xFF
            if bits > MAX_PDO_BITS:
                raise SdoAbortedError(ABORT_PDO_LENGTH)
            return
        if value == 0:
            return
        target, sub, length = int(value) >> 16, (int(value) >> 8) & 0xFF, int(value) & 0xFF
        if target not in self.od:
            raise SdoAbortedError(ABORT_NO_OBJECT)
        var = self._lib_find(target, sub)  # 0x06090011 for a missing sub-index
        if not var.pdo_mappable or len(var) != length:
            raise SdoAbortedError(ABORT_NOT_MAPPABLE)
        if (rx and not var.writable) or (not rx and not var.readable):
            raise SdoAbortedError(ABORT_NOT_MAPPABLE)

    def _configure_consumer(self, value: int | None = None) -> None:
        """0x1016:1 = master node id (bits 16-23) and time in ms (bits 0-15)."""
        if value is None:
            value = self._value(0x1016, 1) if self._has(0x1016, 1) else 0
        self._hb_node = (value >> 16) & 0x7F
        self._hb_watch = _Watch(timeout=(value & 0xFFFF) / 1000.0 if self._hb_node else 0.0)

    def _reload_pdos(self) -> None:
        """The PDO maps as 0x1400-0x1BFF now say (after a write or a boot)."""
        self._pdo_dirty = False
        self.on_routes_changed()
        local = self.local
        for maps, rx in ((_maps(local.rpdo), True), (_maps(local.tpdo), False)):
            for number, pdo_map in maps.items():
                try:
                    pdo_map.read()
                except (SdoAbortedError, KeyError, ValueError) as exc:
                    log.warning("node %d: PDO %d map unreadable: %s", self.node_id, number, exc)
                    continue
                if rx:
                    com = 0x1400 + number - 1
                    timeout = self._value(com, 5) / 1000.0 if self._has(com, 5) else 0.0
                    old = self._rpdo_watch.get(number)
                    watch = _Watch(timeout=timeout)
                    if old is not None:
                        watch.last, watch.fired = old.last, old.fired
                    self._rpdo_watch[number] = watch
                else:
                    self._tpdo.setdefault(number, _TpdoTimer())

    # ------------------------------------------------------------ stepping

    def step(self, now: float | None = None) -> None:
        """Advance to ``now`` (default: the clock): the drive, the heartbeat, TPDO
        timers, the deadline monitors, late SDO answers."""
        with self.lock:
            if now is None:
                now = self.clock()
            self.now = max(self.now, now)
            now = self.now
            if not self.powered:
                return
            self.drive.step(now)
            self._emcy(self._watch_comm(now))
            for task in list(self.periodic.values()):
                if now >= task.due - EPSILON:
                    self._port.send_message(task.can_id, task.data)
                    task.due = max(task.due + task.period, now)
            for item in [q for q in self._sdo_queue if q.due <= now]:
                self._sdo_queue.remove(item)
                if not self.injection.silent:
                    self._port.notify(sdo_rx_id(self.node_id), bytearray(item.data), now)
            if self._pdo_dirty:
                self._reload_pdos()
            if self.nmt_state is NmtState.OPERATIONAL:
                self._event_tpdos(now)

    def _watch_comm(self, now: float) -> list[Emcy]:
        out: list[Emcy] = []
        if self._hb_watch.expired(now):
            log.info("node %d: heartbeat of node %d lost", self.node_id, self._hb_node)
            out += self.drive.comm_lost(now, CommLoss.HEARTBEAT)
        for number, watch in self._rpdo_watch.items():
            if watch.expired(now):
                log.info("node %d: RPDO%d deadline missed", self.node_id, number)
                out += self.drive.comm_lost(now, CommLoss.RPDO)
        return out

    def _event_tpdos(self, now: float) -> None:
        for number, pdo_map in _maps(self.local.tpdo).items():
            tt = pdo_map.trans_type
            if not pdo_map.enabled or tt not in (254, 255):
                continue
            timer = self._tpdo.setdefault(number, _TpdoTimer())
            data = _tpdo_data(self.local, pdo_map)
            inhibit = (pdo_map.inhibit_time or 0) / 10000.0  # 100 us units
            event = (pdo_map.event_timer or 0) / 1000.0
            since = None if timer.last_sent is None else now - timer.last_sent
            changed = data != timer.last_data
            if since is not None and since < inhibit - EPSILON:
                continue
            if changed or since is None or (event > 0 and since >= event - EPSILON):
                self._send_tpdo(now, pdo_map, timer, data)

    def _send_tpdo(self, now: float, pdo_map: PdoMap, timer: _TpdoTimer, data: bytes) -> None:
        timer.last_sent = now
        timer.last_data = data
        if pdo_map.cob_id is not None:
            self._port.send_message(pdo_map.cob_id, data)

    def next_deadline(self) -> float | None:
        """The earliest time :meth:`step` has something to do (None: nothing timed)."""
        with self.lock:
            if not self.powered:
                return None
            times = [t.due for t in self.periodic.values()]
            times += [q.due for q in self._sdo_queue]
            watches = [self._hb_watch, *self._rpdo_watch.values()]
            times += [d for d in (w.deadline() for w in watches) if d is not None]
            return min(times) if times else None

    def _emcy(self, events: Iterable[Emcy]) -> None:
        for e in events:
            if self.nmt_state is NmtState.STOPPED:
                continue  # CiA 301 §7.2.7: no EMCY in stopped
            self.local.emcy.send(e.code, e.register)


def _nothing() -> None:
    return


def _check_sub(od: canopen.ObjectDictionary, index: int, subindex: int) -> None:
    """The library makes up any sub-index of an ARRAY from its first member: only the
    EDS's own sub-indexes exist here (0x06090011 for the others)."""
    obj = od.get(index)
    if isinstance(obj, ODArray) and subindex not in obj.subindices:
        raise SdoAbortedError(ABORT_NO_SUBINDEX)


def _tpdo_data(local: canopen.LocalNode, pdo_map: PdoMap) -> bytes:
    """A TPDO's data from the node's objects as they are now."""
    for var in pdo_map:
        var.set_data(local.get_data(var.index, var.subindex))
    return bytes(pdo_map.data)


def _maps(pdo: PdoBase) -> Mapping[int, PdoMap]:
    return pdo.map if pdo.map is not None else {}


def _map_number(pdo_map: PdoMap) -> int:
    return int(pdo_map.map_array.od.index & 0x1FF) + 1


def _clamp16(value: int) -> int:
    return max(-0x8000, min(0x7FFF, value))


def _set_attr(name: str) -> Callable[[Cia402Drive, int], list[Emcy] | None]:
    def apply(drive: Cia402Drive, value: int) -> list[Emcy] | None:
        setattr(drive, name, value)
        return None

    return apply


def _set_pair(name: str, position: int) -> Callable[[Cia402Drive, int], list[Emcy] | None]:
    def apply(drive: Cia402Drive, value: int) -> list[Emcy] | None:
        pair = list(getattr(drive, name))
        pair[position] = value
        setattr(drive, name, (pair[0], pair[1]))
        return None

    return apply


def _set_mode(drive: Cia402Drive, value: int) -> list[Emcy] | None:
    drive.mode = Mode(value)
    return None


def _set_controlword(drive: Cia402Drive, value: int) -> list[Emcy] | None:
    return drive.set_controlword(drive.last, value)


_LIVE: dict[tuple[int, int], Callable[[Cia402Drive], int]] = {
    # objects read from the drive model as it is now (SDO upload, TPDO)
    (cia402.STATUSWORD, 0): lambda d: d.statusword,
    (cia402.ERROR_CODE, 0): lambda d: d.error_code,
    (0x1001, 0): lambda d: d.error_register,
    (cia402.VL_VELOCITY_ACTUAL, 0): lambda d: _clamp16(d.velocity_actual),
    (cia402.VL_VELOCITY_DEMAND, 0): lambda d: _clamp16(d.velocity_demand),
    (cia402.VELOCITY_ACTUAL, 0): lambda d: d.velocity_actual,
    (cia402.TORQUE_ACTUAL, 0): lambda d: d.torque_permille,
    (cia402.CURRENT_ACTUAL, 0): lambda d: d.current_permille,
    (cia402.MODES_OF_OPERATION_DISPLAY, 0): lambda d: int(d.mode),
    (0x2000, 3): lambda d: d.last_fault,
}

_INPUTS: dict[tuple[int, int], Callable[[Cia402Drive, int], list[Emcy] | None]] = {
    (cia402.CONTROLWORD, 0): _set_controlword,
    (cia402.VL_TARGET_VELOCITY, 0): _set_attr("vl_target"),
    (cia402.TARGET_VELOCITY, 0): _set_attr("pv_target"),
    (cia402.MODES_OF_OPERATION, 0): _set_mode,
    (cia402.QUICK_STOP_OPTION, 0): _set_attr("quick_stop_option"),
    (0x605B, 0): _set_attr("shutdown_option"),
    (0x605C, 0): _set_attr("disable_operation_option"),
    (0x605E, 0): _set_attr("fault_reaction_option"),
    (cia402.ABORT_CONNECTION_OPTION, 0): _set_attr("abort_connection_option"),
    (0x6046, 1): _set_attr("vl_min"),
    (0x6046, 2): _set_attr("vl_max"),
    (0x6048, 1): _set_pair("vl_accel", 0),
    (0x6048, 2): _set_pair("vl_accel", 1),
    (0x6049, 1): _set_pair("vl_decel", 0),
    (0x6049, 2): _set_pair("vl_decel", 1),
    (0x6083, 0): _set_attr("profile_accel"),
    (0x6084, 0): _set_attr("profile_decel"),
    (0x6075, 0): _set_attr("rated_current_ma"),
}
