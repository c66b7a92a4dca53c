"""The 3D view's tickets and cookies (`server/viewer/passes.py`), on a clock of the test's own."""

from __future__ import annotations

from http import HTTPStatus

import pytest

from server.viewer.gate import cookie_values, target
from server.viewer.passes import MAX_PASSES, SESSION_S, TICKET_S, Pass, Passes, PassRefused


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_a_ticket_is_good_once_for_a_cookie_that_allows_what_it_did() -> None:
    passes = Passes(Clock())
    granted = Pass(run=7, organiser=False)
    ticket = passes.issue(granted)
    cookie, got = passes.redeem(ticket, 7)
    assert got == granted and passes.session(cookie) == granted
    with pytest.raises(PassRefused) as e:
        passes.redeem(ticket, 7)
    assert e.value.status is HTTPStatus.UNAUTHORIZED
    assert passes.session("made-up") is None and passes.session(None) is None


def test_a_ticket_for_one_run_is_refused_elsewhere_and_stays_good() -> None:
    passes = Passes(Clock())
    ticket = passes.issue(Pass(run=7, organiser=False))
    for where in (8, None):
        with pytest.raises(PassRefused) as e:
            passes.redeem(ticket, where)
        assert e.value.status is HTTPStatus.FORBIDDEN
    passes.redeem(ticket, 7)


def test_the_organisers_ticket_opens_any_url() -> None:
    passes = Passes(Clock())
    _, got = passes.redeem(passes.issue(Pass(run=None, organiser=True)), None)
    assert got.organiser and got.run is None


def test_tickets_and_cookies_expire() -> None:
    clock = Clock()
    passes = Passes(clock)
    late = passes.issue(Pass(run=1, organiser=False))
    cookie, _ = passes.redeem(passes.issue(Pass(run=1, organiser=False)), 1)
    clock.now += TICKET_S
    with pytest.raises(PassRefused, match="expired"):
        passes.redeem(late, 1)
    clock.now += SESSION_S - TICKET_S - 1
    assert passes.session(cookie) is not None
    clock.now += 1
    assert passes.session(cookie) is None


def test_past_max_passes_the_oldest_go() -> None:
    passes = Passes(Clock())
    first = passes.issue(Pass(run=1, organiser=False))
    for _ in range(MAX_PASSES):
        passes.issue(Pass(run=1, organiser=False))
    with pytest.raises(PassRefused):
        passes.redeem(first, 1)


def test_the_gate_reads_a_heads_query_and_its_view_cookies() -> None:
    head = b"GET /run/7?ticket=abc&darkMode HTTP/1.1\r\nHost: x\r\n\r\n"
    assert target(head) == ("/run/7", [("ticket", "abc"), ("darkMode", "")])
    assert target(b"nonsense\r\n\r\n") == ("", [])
    headers = {"cookie": "a=1; srlab_view_8080=one; srlab_view_8081=x;srlab_view_8080=two"}
    assert cookie_values(headers, "srlab_view_8080") == ["one", "two"]
    assert cookie_values({}, "srlab_view_8080") == []
