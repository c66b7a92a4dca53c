"""SRLAB_* settings as a user writes them in a shell or an env file."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

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
