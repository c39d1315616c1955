"""One root for every error of the project; decode errors are ValueError, timeouts TimeoutError."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import adapters
import gateway
from gateway.errors import (
    CommandRejected,
    ConfigError,
    ConfigErrors,
    FrameDecodeError,
    GatewayError,
    GatewayTimeout,
    ParameterError,
    ParameterNotWritable,
    UnknownDrive,
)

NOT_A_REQUEST_TIMEOUT = {
    # the rest of a fragmented message never came: the partial message is dropped like a
    # frame that does not decode; no request of the gateway went unanswered
    "adapters.devicenet.errors.ReassemblyTimeout",
}


def project_errors() -> list[type[BaseException]]:
    found: dict[str, type[BaseException]] = {}
    for package in (gateway, adapters):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            if info.name.endswith("__main__"):
                continue
            module = importlib.import_module(info.name)
            for _, obj in inspect.getmembers(module, inspect.isclass):
                if issubclass(obj, BaseException) and obj.__module__ == info.name:
                    found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return sorted(found.values(), key=lambda c: f"{c.__module__}.{c.__qualname__}")


ERRORS = project_errors()


def test_the_project_defines_errors() -> None:
    assert len(ERRORS) > 20  # the walk found the adapters' errors too


@pytest.mark.parametrize("cls", ERRORS, ids=lambda c: f"{c.__module__}.{c.__qualname__}")
def test_every_error_is_under_the_one_root(cls: type[BaseException]) -> None:
    assert issubclass(cls, GatewayError)
    name = f"{cls.__module__}.{cls.__qualname__}"
    if cls.__name__.endswith("DecodeError"):
        assert issubclass(cls, FrameDecodeError) and issubclass(cls, ValueError), name
    if cls.__name__.endswith("Timeout") and name not in NOT_A_REQUEST_TIMEOUT:
        assert issubclass(cls, GatewayTimeout) and issubclass(cls, TimeoutError), name


def test_builtin_leaves_catch_either_way() -> None:
    raw = b"\x68\x01"
    with pytest.raises(ValueError, match="bad frame"):
        raise FrameDecodeError("bad frame", raw)
    assert FrameDecodeError("x", raw).raw == raw
    with pytest.raises(TimeoutError):
        raise GatewayTimeout("no answer")
    with pytest.raises(KeyError):
        raise UnknownDrive("no drive 'x'")
    for exc in (CommandRejected("no"), ConfigErrors([ConfigError("f", "k", "r")])):
        assert isinstance(exc, ValueError)
    assert str(ConfigError("site.toml", "a.b", "is wrong")) == "site.toml: a.b: is wrong"
    assert str(ParameterError("parameter value out of limits", code=2)) == (
        "error 0x0002: parameter value out of limits"
    )
    assert issubclass(ParameterNotWritable, ParameterError)
