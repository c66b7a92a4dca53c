"""SRLAB_* settings as a user writes them in a shell or an env file."""

from __future__ import annotations

import pytest
from pydantic import ValidationError

from bench.liveserver import free_port
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


@pytest.mark.parametrize(
    ("overrides", "says"),
    [
        ({"host": "0.0.0.0"}, "it listens on 0.0.0.0 (SRLAB_HOST)"),
        ({"forwarded_allow_ips": ["127.0.0.1"]}, "SRLAB_FORWARDED_ALLOW_IPS trusts a proxy"),
        ({"allowed_hosts": ["localhost", "srlab.lab"]}, "SRLAB_ALLOWED_HOSTS names srlab.lab"),
        ({"allowed_hosts": ["*"]}, "SRLAB_ALLOWED_HOSTS names *"),
        (
            {"cors_origins": ["http://localhost:5173", "https://lab.example"]},
            "SRLAB_CORS_ORIGINS lets pages of https://lab.example write",
        ),
        ({"cors_origins": ["*"]}, "SRLAB_CORS_ORIGINS lets pages of * write"),
    ],
)
def test_a_service_reachable_from_elsewhere_needs_the_token(
    overrides: dict[str, object], says: str
) -> None:
    settings = Settings(**overrides)  # type: ignore[arg-type]
    with pytest.raises(ValueError) as e:
        settings.check()
    [line] = str(e.value).splitlines()
    assert line.startswith("srlab is reachable from beyond this machine (")
    assert says in line and "set SRLAB_TOKEN" in line
    with_token = Settings(**overrides, token="s3cret")  # type: ignore[arg-type]
    with_token.check()
    assert with_token.writes_need_token


def test_names_and_origins_of_this_machine_alone_need_no_token() -> None:
    settings = Settings(
        allowed_hosts=["localhost", "127.0.0.2", "[::1]", "::1"],
        cors_origins=["http://localhost:5173", "http://127.0.0.1:3000", "http://[::1]:3000"],
    )
    settings.check()
    assert settings.reachable_through() == []
    assert not settings.writes_need_token
    assert Settings(token="s3cret").writes_need_token  # a token set is asked for


def test_serve_behind_a_proxy_without_a_token_is_refused_in_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("SRLAB_TOKEN", raising=False)
    monkeypatch.setenv("SRLAB_FORWARDED_ALLOW_IPS", "127.0.0.1")
    monkeypatch.setenv("SRLAB_ALLOWED_HOSTS", "srlab.example")
    # Were it not refused, it would stop at this database instead of serving.
    monkeypatch.setenv("SRLAB_DATABASE_URL", "sqlite:////proc/srlab.db")
    monkeypatch.setenv("SRLAB_PORT", str(free_port()))
    monkeypatch.setenv("SRLAB_VISER", "false")
    with pytest.raises(SystemExit) as e:
        main(["serve"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    [line] = err.splitlines()
    assert "SRLAB_FORWARDED_ALLOW_IPS" in line and "SRLAB_ALLOWED_HOSTS names srlab.example" in line
    assert "set SRLAB_TOKEN" in line and "Traceback" not in err


def test_reads_kept_to_tokens_go_with_the_3d_view_whose_gate_asks_for_tickets() -> None:
    Settings(reads="token", token="s3cret").check()
    Settings(reads="token", token="s3cret", viser=False).check()
    Settings(token="s3cret").check()  # reads open: the view as it is
