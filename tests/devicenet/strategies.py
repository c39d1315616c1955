"""Hypothesis strategies for the DeviceNet codec tests."""

from __future__ import annotations

from hypothesis import strategies as st

from adapters.devicenet.codec.explicit import (
    AllocateConnectionSet,
    AllocateResponse,
    Body,
    BodyFormat,
    ErrorResponse,
    ExplicitMessage,
    GenericRequest,
    GetAttributesAll,
    GetAttributeSingle,
    ReleaseConnectionSet,
    Reset,
    SetAttributesAll,
    SetAttributeSingle,
    SuccessResponse,
)
from adapters.devicenet.codec.frame import CanFrame
from adapters.devicenet.codec.objects import AllocationChoice

macs = st.integers(0, 63)
bytes8 = st.integers(0, 0xFF)
ids11 = st.integers(0, 0x7FF)
can_data = st.binary(max_size=8)
frames = st.builds(CanFrame, ids11, can_data)
choices = st.builds(AllocationChoice, bytes8)
_DEDICATED_REQUESTS = {0x01, 0x02, 0x05, 0x0E, 0x10, 0x4B, 0x4C}
_DEDICATED_RESPONSES = {0x14, 0x4B}


def paths(
    body_format: BodyFormat = BodyFormat.CLASS8_INSTANCE8,
) -> st.SearchStrategy[tuple[int, int]]:
    class_max = (
        0xFF
        if body_format in (BodyFormat.CLASS8_INSTANCE8, BodyFormat.CLASS8_INSTANCE16)
        else 0xFFFF
    )
    instance_max = (
        0xFF
        if body_format in (BodyFormat.CLASS8_INSTANCE8, BodyFormat.CLASS16_INSTANCE8)
        else 0xFFFF
    )
    return st.tuples(st.integers(0, class_max), st.integers(0, instance_max))


def requests(body_format: BodyFormat = BodyFormat.CLASS8_INSTANCE8) -> st.SearchStrategy[Body]:
    p = paths(body_format)
    data = st.binary(max_size=40)
    return st.one_of(
        st.builds(lambda ci, a: GetAttributeSingle(ci[0], ci[1], a), p, bytes8),
        st.builds(
            lambda ci, a, v: SetAttributeSingle(ci[0], ci[1], a, v),
            p,
            bytes8,
            st.binary(min_size=1, max_size=40),
        ),
        st.builds(lambda ci: GetAttributesAll(ci[0], ci[1]), p),
        st.builds(lambda ci, d: SetAttributesAll(ci[0], ci[1], d), p, data),
        st.builds(lambda ci, t: Reset(ci[0], ci[1], t), p, st.none() | bytes8),
        st.builds(lambda ci, c, m: AllocateConnectionSet(c, m, ci[0], ci[1]), p, choices, macs),
        st.builds(lambda ci, c: ReleaseConnectionSet(c, ci[0], ci[1]), p, choices),
        st.builds(
            lambda s, ci, d: GenericRequest(s, ci[0], ci[1], d),
            st.integers(0, 0x7F).filter(lambda s: s not in _DEDICATED_REQUESTS),
            p,
            data,
        ),
    )


responses: st.SearchStrategy[Body] = st.one_of(
    st.builds(
        SuccessResponse,
        st.integers(0, 0x7F).filter(lambda s: s not in _DEDICATED_RESPONSES),
        st.binary(max_size=40),
    ),
    st.builds(AllocateResponse, bytes8),
    st.builds(ErrorResponse, bytes8, bytes8),
)


def messages(
    body_format: BodyFormat = BodyFormat.CLASS8_INSTANCE8,
) -> st.SearchStrategy[ExplicitMessage]:
    return st.builds(ExplicitMessage, macs, st.booleans(), requests(body_format) | responses)
