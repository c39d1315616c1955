"""The master engine's short cuts on received TPDO1s, checked against its general path.

A drive at rest repeats its TPDO1 every SYNC: the engine gives the same :class:`Inputs`
again without decoding (``Master._on_tpdo``), and unpacks a mapping of whole 1, 2, 4 and
8 byte fields with one struct (``_pdo_struct``). A reference engine, stepped with the
same events and forced onto the general path before every step (no remembered TPDO1,
no struct), must give the same actions and end in the same node state at every step.
"""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.canopen.codec import cia402
from adapters.canopen.codec import frames as f
from adapters.canopen.codec.cia402 import State
from adapters.canopen.errors import CanOpenDecodeError
from adapters.canopen.master import Action, Event, FrameIn, Master, PdoField
from adapters.canopen.master.engine import _pdo_struct, _unpack
from adapters.canopen.master.node import Node
from tests.canopen.test_master import CYCLE, FakeNode, Line, config, node_config

NODE = 5

statuswords = st.sampled_from(
    [cia402.statusword_bits(s) | cia402.SW_REMOTE for s in State]
    + [0x0223 | cia402.SW_TARGET_REACHED, 0x004F, 0xFFFF, 0x0000]
)
tpdo_data = st.one_of(
    st.builds(
        lambda sw, v: sw.to_bytes(2, "little") + v.to_bytes(2, "little", signed=True),
        statuswords,
        st.sampled_from([0, 1, -1, 1200, -32768]),
    ),
    st.binary(max_size=3),  # short: a bad PDO
    st.binary(min_size=5, max_size=8),  # longer than the mapping: the rest ignored
)
events = st.lists(
    st.one_of(
        st.tuples(st.just("tpdo"), tpdo_data),
        st.tuples(st.just("tpdo_again"), st.just(b"")),  # the last TPDO1 repeated
        st.tuples(st.just("heartbeat"), st.sampled_from([0x05, 0x7F, 0x00, 0x04])),
        st.tuples(st.just("state"), st.sampled_from(list(State))),  # the drive moves
        st.tuples(st.just("run"), st.sampled_from([CYCLE, 0.1, 0.5])),  # heartbeats, TPDOs
    ),
    max_size=30,
)


def _brought_up(general: bool) -> tuple[Line, FakeNode]:
    node = FakeNode(NODE)
    master = Master(config(), [node_config()])
    if general:
        step = master.step

        def general_step(now: float, event: Event | None = None) -> list[Action]:
            for n in master.nodes.values():  # forced onto the general path
                n.tpdo_data = n.tpdo_inputs = None
                n.tpdo_struct = None
            return step(now, event)

        master.step = general_step  # type: ignore[method-assign]
    line = Line(master, node)
    line.run(0.5)
    return line, node


def _state(n: Node) -> tuple[object, ...]:
    return (
        n.phase,
        n.statusword,
        n.state,
        n.heard,
        n.seen,
        [(j.purpose, j.index, j.subindex) for j in n.jobs],
        None if n.current is None else (n.current.purpose, n.current.index),
        dict(n.figures),
        n.fault_pending,
    )


@settings(max_examples=150, deadline=None)
@given(events)
def test_the_short_cuts_give_what_the_general_path_gives(script: list[tuple[str, object]]) -> None:
    lines = [_brought_up(general=False), _brought_up(general=True)]
    assert all(line.master.online(NODE) for line, _ in lines)
    last = b""
    for what, arg in script:
        for line, node in lines:
            if what == "run":
                assert isinstance(arg, float)
                line.run(arg)
            elif what == "state":
                assert isinstance(arg, State)
                node.state = arg
            elif what == "heartbeat":
                assert isinstance(arg, int)
                line.inject(f.CanFrame(f.HEARTBEAT_BASE + NODE, bytes((arg,))))
            else:
                if what == "tpdo":
                    assert isinstance(arg, bytes)
                    last = arg
                line.inject(f.CanFrame(f.tpdo_id(1, NODE), last))
        (fast, _), (slow, _) = lines
        assert fast.actions == slow.actions
        assert fast.sent == slow.sent
        assert _state(fast.master.nodes[NODE]) == _state(slow.master.nodes[NODE])
        assert fast.master.next_deadline() == slow.master.next_deadline()
    (fast, _), _ = lines
    assert fast.master.nodes[NODE].figures["tpdo_rx"] > 0


sizes = st.sampled_from([8, 12, 16, 24, 32, 40, 64])
mappings = st.lists(
    st.builds(
        lambda bits, signed: PdoField(f.MappingEntry(0x6000, 0, bits), signed=signed),
        sizes,
        st.booleans(),
    ),
    min_size=1,
    max_size=4,
)


@given(mappings, st.binary(max_size=8))
def test_the_struct_unpacks_as_the_general_path(fields_: list[PdoField], data: bytes) -> None:
    compiled = _pdo_struct(fields_)
    if any(p.entry.bits not in (8, 16, 32, 64) for p in fields_):
        assert compiled is None
    try:
        want: tuple[int, ...] | None = _unpack(fields_, data)
    except CanOpenDecodeError:
        want = None
    try:
        got: tuple[int, ...] | None = _unpack(fields_, data, compiled)
    except CanOpenDecodeError:
        got = None
    assert got == want


def test_a_repeated_tpdo_is_the_same_inputs_and_is_counted() -> None:
    line, node = _brought_up(general=False)
    frame = node.tpdo(7)
    line.master.nodes[NODE].tpdo_credit = 2  # two SYNCs' worth: no conflict here
    first = line.master.step(line.now, FrameIn(frame))
    again = line.master.step(line.now, FrameIn(f.CanFrame(frame.cob_id, bytes(frame.data))))
    assert again == first and again[0] is first[0]  # not decoded again
    assert line.master.nodes[NODE].figures["tpdo_rx"] >= 2
