"""``[history]`` in the config: defaults, paths, and every bad key named."""

from __future__ import annotations

from pathlib import Path

import pytest

from gateway.config import DEFAULT_CONFIG, DEFAULT_HISTORY_PATH, load
from gateway.errors import ConfigErrors


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "site.toml"
    path.write_text(text)
    return path


def test_off_by_default_at_the_state_directory(tmp_path: Path) -> None:
    config = load(write(tmp_path, ""))
    assert config.history.enabled is False
    assert config.history.path == DEFAULT_HISTORY_PATH
    assert config.zenoh.recovery_cache == 100


def test_on_in_the_demo_under_the_users_home() -> None:
    history = load(DEFAULT_CONFIG).history
    assert history.enabled
    assert history.path == Path.home() / ".local/state/drive-gateway/demo-history.sqlite"


def test_a_relative_path_is_beside_the_config(tmp_path: Path) -> None:
    config = load(write(tmp_path, '[history]\nenabled = true\npath = "h/x.sqlite"\n'))
    assert config.history.path == tmp_path / "h" / "x.sqlite"


@pytest.mark.parametrize(
    ("text", "key", "words"),
    [
        ("period = 0", "history.period", "0.05"),
        ("batch_interval = 100", "history.batch_interval", "60"),
        ("max_age = 10", "history.max_age", "60"),
        ("max_size_mb = 0", "history.max_size_mb", "1"),
        ('path = ""', "history.path", "not a file path"),
        ("enabled = 1", "history.enabled", "true or false"),
        ("perod = 1", "history.perod", "period"),
    ],
)
def test_bad_keys_are_named(tmp_path: Path, text: str, key: str, words: str) -> None:
    with pytest.raises(ConfigErrors) as caught:
        load(write(tmp_path, f"[history]\n{text}\n"))
    errors = caught.value.errors
    assert any(e.key == key and words in str(e) for e in errors), [str(e) for e in errors]


def test_a_bad_recovery_cache_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigErrors) as caught:
        load(write(tmp_path, "[zenoh]\nrecovery_cache = -1\n"))
    assert any(e.key == "zenoh.recovery_cache" for e in caught.value.errors)
