"""What a CAN bus may hand the link, for the hypothesis tests of the adapters' received
frame (``CanFrame.from_bus``): identifiers and data of every kind, in range or not, and
whether a classic 11-bit frame carries them (CAN 2.0A: 11-bit identifier, 0-8 bytes)."""

from __future__ import annotations

from hypothesis import strategies as st

MAX_STANDARD_ID = 0x7FF
MAX_CLASSIC_DATA = 8


class IntId(int):
    """An int subclass (an IntEnum-like identifier): not a one-test path's type, still valid."""


IDENTIFIERS = st.one_of(
    st.integers(-2, MAX_STANDARD_ID + 3),
    st.booleans(),
    st.integers(0, MAX_STANDARD_ID).map(IntId),
    st.just(389.0),
)
DATA = st.binary(max_size=MAX_CLASSIC_DATA + 1).flatmap(
    lambda b: st.sampled_from([b, bytearray(b)])
)


def carried(identifier: object, data: bytes | bytearray, extended: bool) -> bool:
    """Whether a classic frame with an 11-bit identifier carries it."""
    return (
        not extended
        and isinstance(identifier, int)
        and not isinstance(identifier, bool)
        and 0 <= identifier <= MAX_STANDARD_ID
        and len(data) <= MAX_CLASSIC_DATA
    )
