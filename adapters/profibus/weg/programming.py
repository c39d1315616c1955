"""What a WEG drive is programmed with, against its config, at connect.

``startup_params`` are written where the drive differs and read back; P0741 (the data
profile) must be the config's, or the words would be misread; with ``verify_mapping`` the
telegram size (P0922 / P751) and the word mapping (P0742.., P0750..) are compared too. A
written P0741 or telegram size is in force only once the drive has left cyclic data
(:class:`DataProfilePending`).
"""

from __future__ import annotations

from adapters.profibus.contract import DiagKind, EventSink, RecordChannel
from adapters.profibus.weg import words as w
from adapters.profibus.weg.options import WegOptions
from adapters.profibus.weg.records import RecordParams
from adapters.profibus.weg.spec import DataProfile, ModelSpec
from gateway.errors import GatewayError, ParameterError


class DriveProgrammingMismatch(GatewayError):
    """The drive's programming (P0741, P0922/P751, P0742..) differs from the drive's config."""


class DataProfilePending(GatewayError):
    """A ``startup_params`` write the drive takes only without cyclic data (P0741, P0922 /
    P751: CFW-11 l.959-961, CFW700 l.922-924 and l.1172, CFW320 l.547 and l.581) was made.

    The drive still speaks its old words until it leaves data exchange: the adapter takes
    the slave out of data exchange and parameterises it again (``reparameterise``), and the
    next connect finds the value in force (issue 32 item 2)."""

    reparameterise = True


class StartupParamRefused(ParameterError):
    """The drive refused a ``startup_params`` write: it stays "not configured".

    Reads as the reason an operator sees: "startup P0313 = 9: parameter value out of the
    limits (error 0x0002)".
    """

    def __str__(self) -> str:
        code = "" if self.code is None else f" (error 0x{self.code:04X})"
        return f"{self.text}{code}"


async def write_startup_param(
    params: RecordParams,
    channel: RecordChannel,
    event: EventSink,
    spec: ModelSpec,
    entry: tuple[int, int],
) -> bool:
    """Write one ``startup_params`` entry (number, value) where the drive differs; True
    when written."""
    number, value = entry
    name = spec.pname(number)
    raw = w.to_word(value)
    written = False
    try:
        if await params.read(channel, number) != raw:
            written = True
            await params.write(channel, number, raw)
            event(
                f"startup {name} = {value} written",
                DiagKind.PARAMETER,
                number=number,
                value=value,
            )
        back = await params.read(channel, number)
    except ParameterError as exc:
        raise StartupParamRefused(f"startup {name} = {value}: {exc.text}", exc.code) from exc
    if back != raw:
        raise DriveProgrammingMismatch(f"startup {name} = {value}: read back {back}")
    return written


async def check_factory_settings(
    params: RecordParams,
    channel: RecordChannel,
    event: EventSink,
    spec: ModelSpec,
    options: WegOptions,
) -> dict[str, int]:
    """Read the parameters the manual says must keep their factory settings (CFW320 2.4
    WARNING: P308, P310, P311, P312 "must be programmed with the factory settings" for the
    Profibus DP module to work); a difference is one ``config`` event naming each. Their
    values, by name, for ``DriveState.values``. The factory values are the spec's unless
    the drive's ``factory_settings`` key gives its own."""
    expected = {**spec.factory_settings, **dict(options.factory_settings)}
    if not expected:
        return {}
    numbers = sorted(expected)
    got = await params.read_many(channel, [(n, 0) for n in numbers])
    wrong = [
        f"{spec.pname(n)} = {value} (factory setting {expected[n]})"
        for n, value in zip(numbers, got, strict=True)
        if value != expected[n]
    ]
    if wrong:
        names = ", ".join(spec.pname(n) for n in numbers)
        event(
            f"{', '.join(wrong)}: the {spec.device.value} manual requires {names} at their "
            "factory settings for the Profibus DP module to work",
            DiagKind.CONFIG,
            **{spec.pname(n): v for n, v in zip(numbers, got, strict=True)},
        )
    return {spec.pname(n): v for n, v in zip(numbers, got, strict=True)}


def check_data_profile(spec: ModelSpec, want: DataProfile, got: int) -> None:
    """P741 against the configured data profile (CFW320 Table 4.6 note: the control,
    status, speed reference and motor speed words depend on it): a mismatch would be
    misread, so the drive is not brought online."""
    if got == want.p0741:
        return
    names = {p.p0741: p.value for p in DataProfile}
    raise DriveProgrammingMismatch(
        f"{spec.pname(741)} = {got} ({names.get(got, 'unknown data profile')}), "
        f"the config's data_profile is {want.value} ({spec.pname(741)} = {want.p0741}): "
        "its words would be misread"
    )


def expected_programming(
    spec: ModelSpec, options: WegOptions, in_map: tuple[int, ...], out_map: tuple[int, ...]
) -> list[tuple[int, int]]:
    """(parameter, expected raw value) that the config implies about the drive."""
    out = [(spec.telegram_param, spec.telegram_code(options.words))]
    if len(spec.profiles) > 1 and not spec.reads_data_profile:
        out.append((741, options.data_profile.p0741))
    for i, param in enumerate(in_map):
        out.append((spec.read_map_param(i + 3), param))
    for i, param in enumerate(out_map):
        out.append((spec.write_map_param(i + 3), param))
    return out


async def verify_programming(
    params: RecordParams,
    channel: RecordChannel,
    spec: ModelSpec,
    expected: list[tuple[int, int]],
) -> None:
    """Read the ``expected`` parameters: a difference is a :class:`DriveProgrammingMismatch`."""
    values = await params.read_many(channel, [(n, 0) for n, _ in expected])
    wrong = [
        f"{spec.pname(n)} = {got} (config: {want})"
        for (n, want), got in zip(expected, values, strict=True)
        if got != want
    ]
    if wrong:
        raise DriveProgrammingMismatch(
            "the drive is programmed differently from its config: " + ", ".join(wrong)
        )
