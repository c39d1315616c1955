"""The simulated drive as programmed at the HMI before power-up: the parameters a telegram
size, data profile and word mapping need (P0918 / P750, P0922 / P751, P0741, P0742.. and
P0750.. / P746..), and the motor its parameters describe.
"""

from __future__ import annotations

from collections.abc import Mapping

from adapters.profibus.weg import spec as specs
from adapters.profibus.weg.spec import DataProfile, ModelSpec
from gateway.sim import MotorParams


def programming(
    spec: ModelSpec,
    *,
    address: int,
    n_words: int,
    profile: DataProfile,
    frame: int,
    words_in: tuple[int, ...],
    words_out: tuple[int, ...],
) -> list[tuple[int, int]]:
    """(parameter, value) of the drive's programming; ValueError for one the model has not
    (a data profile, frame 20, the telegram size)."""
    if profile not in spec.profiles or (frame == 20 and not spec.frame20):
        raise ValueError(f"the {spec.device.value} has no {profile.value} frame {frame}")
    if frame == 20:
        n_words, words_in, words_out = (
            specs.FRAME20_WORDS,
            specs.FRAME20_INPUTS,
            specs.FRAME20_OUTPUTS,
        )
    if not 2 <= n_words <= spec.max_words:
        raise ValueError(f"the {spec.device.value} takes 2..{spec.max_words} words")
    out = [(spec.address_param, address), (spec.telegram_param, spec.telegram_code(n_words))]
    if len(spec.profiles) > 1:
        out.append((741, profile.p0741))
    for i, param in enumerate(words_in):
        out.append((spec.read_map_param(i + 3), param))
    for i, param in enumerate(words_out):
        out.append((spec.write_map_param(i + 3), param))
    return out


def motor_params(values: Mapping[int, int]) -> MotorParams:
    """The motor of P0134 (maximum speed), P0100 / P0101 (ramps) and P0401 (current)."""
    v = values
    return MotorParams(
        rated_rpm=max(float(v[134]), 1.0),
        accel_time=v[100] / 10.0,
        decel_time=v[101] / 10.0,
        rated_current=max(v[401] / 10.0, 0.1),
        magnetising_current=max(v[401] / 10.0, 0.1) * 0.3,
    )
