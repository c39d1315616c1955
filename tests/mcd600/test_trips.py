"""The trip code table (guide 4.5)."""

from __future__ import annotations

import pytest

from adapters.mcd600.trips import INTERNAL_FAULTS, TRIP_TEXTS, is_listed, trip_text


def test_listed_codes() -> None:
    assert trip_text(2) == "Motor overload"
    assert trip_text(1) == "Excess start time"
    assert trip_text(16) == "Network forced trip"
    assert trip_text(83) == "Low control volts"
    assert trip_text(0) == "No trip"


@pytest.mark.parametrize("code", [84, 90, 96])
def test_internal_faults_carry_their_code(code: int) -> None:
    text = trip_text(code)
    assert text.startswith(f"Internal fault {code}")
    assert is_listed(code)


@pytest.mark.parametrize("code", [20, 25, 97, 200, 255])
def test_unknown_codes_keep_only_their_number(code: int) -> None:
    assert trip_text(code) == f"Trip code {code}"
    assert not is_listed(code)


def test_table_covers_the_guide() -> None:
    # the guide lists 0-19, 23, 24, 26-31, 33-36, 47, 48, 56-60, 70-83 and 84-96
    expected = (
        set(range(20))
        | {23, 24}
        | set(range(26, 32))
        | set(range(33, 37))
        | {47, 48}
        | set(range(56, 61))
        | set(range(70, 84))
    )
    assert set(TRIP_TEXTS) == expected
    assert list(INTERNAL_FAULTS) == list(range(84, 97))
