"""SRLAB_* settings as a user writes them in a shell or an env file."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from server.cli import main
from server.config import Settings


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("10.0.0.5", ["10.0.0.5"]),
        ("10.0.0.5, 10.0.1.0/24,", ["10.0.0.5", "10.0.1.0/24"]),
        ('["10.0.0.5", "*"]', ["10.0.0.5", "*"]),
        ("::1", ["::1"]),
        ("", []),
    ],
)
def test_lists_are_json_or_comma_separated(
    monkeypatch: pytest.MonkeyPatch, text: str, expected: list[str]
) -> None:
    monkeypatch.setenv("SRLAB_FORWARDED_ALLOW_IPS", text)
    monkeypatch.setenv("SRLAB_ALLOWED_HOSTS", text.replace("10.0.1.0/24", "srlab.lab"))
    settings = Settings()
    assert settings.forwarded_allow_ips == expected
    assert settings.allowed_hosts == [e.replace("10.0.1.0/24", "srlab.lab") for e in expected]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("proxy.lab", "'proxy.lab' is not an IP address or network"),
        ("10.0.0.5/24", "'10.0.0.5/24' is not an IP address or network"),  # host bits set
        ('["10.0.0.5"', "not a JSON list"),
    ],
)
def test_a_bad_proxy_list_is_refused_with_a_message(
    monkeypatch: pytest.MonkeyPatch, text: str, message: str
) -> None:
    monkeypatch.setenv("SRLAB_FORWARDED_ALLOW_IPS", text)
    with pytest.raises(ValidationError, match=message):
        Settings()


def test_proxy_headers_are_ignored_unless_a_proxy_is_trusted() -> None:
    assert Settings().forwarded_allow_ips == []


def test_bad_settings_name_their_variables_one_line_each(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SRLAB_MAX_RUNS", "many")
    monkeypatch.setenv("SRLAB_VISER", "maybe")
    with pytest.raises(ValueError) as e:
        Settings.load(port=0)
    lines = str(e.value).splitlines()
    assert len(lines) == 3
    assert lines[0].startswith("SRLAB_PORT: ") and lines[0].endswith(", got 0")
    assert lines[1].startswith("SRLAB_MAX_RUNS: ") and lines[1].endswith(", got 'many'")
    assert lines[2].startswith("SRLAB_VISER: ")
    monkeypatch.delenv("SRLAB_MAX_RUNS")
    monkeypatch.delenv("SRLAB_VISER")
    assert Settings.load(port=8001).port == 8001


def test_serve_with_a_bad_setting_exits_2_without_a_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("SRLAB_REWARD_RATE_PER_S", "-1")
    with pytest.raises(SystemExit) as e:
        main(["serve"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("srlab: error: SRLAB_REWARD_RATE_PER_S: ")
    assert "got '-1'" in err and "Traceback" not in err and "pydantic.dev" not in err
