"""The 3D view's tickets and cookies (`server/viewer/passes.py`), on a clock of the test's own."""

from __future__ import annotations

from http import HTTPStatus

import pytest

from server.viewer.heads import cookie_values, target
from server.viewer.passes import (
    MAX_PASSES,
    PER_RUN,
    SESSION_S,
    TICKET_S,
    Pass,
    Passes,
    PassRefused,
)


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
    organiser = Pass(run=None, organiser=True)
    first, second = passes.issue(organiser), passes.issue(organiser)
    for _ in range(MAX_PASSES - 1):
        passes.issue(organiser)
    with pytest.raises(PassRefused):
        passes.redeem(first, None)
    passes.redeem(second, None)


def test_one_runs_passes_past_per_run_push_out_that_runs_oldest_alone() -> None:
    passes = Passes(Clock())
    other = passes.issue(Pass(run=2, organiser=False))
    cookies = [passes.redeem(passes.issue(Pass(run=1, organiser=False)), 1)[0] for _ in range(3)]
    tickets = [passes.issue(Pass(run=1, organiser=False)) for _ in range(PER_RUN + 1)]
    with pytest.raises(PassRefused):
        passes.redeem(tickets[0], 1)  # the run's oldest ticket went
    for ticket in tickets[1:6]:  # (redeemed: 3 cookies before, 5 now, PER_RUN = 8)
        passes.redeem(ticket, 1)
    assert all(passes.session(c) is not None for c in cookies)
    passes.redeem(tickets[6], 1)  # the 9th cookie of run 1: its oldest goes
    assert passes.session(cookies[0]) is None and passes.session(cookies[1]) is not None
    passes.redeem(other, 2)  # another run's are untouched


def test_the_gate_reads_a_heads_query_and_its_view_cookies() -> None:
    head = b"GET /run/7?ticket=abc&darkMode HTTP/1.1\r\nHost: x\r\n\r\n"
    assert target(head) == ("/run/7", [("ticket", "abc"), ("darkMode", "")])
    assert target(b"nonsense\r\n\r\n") == ("", [])
    headers = {"cookie": "a=1; srlab_view_8080=one; srlab_view_8081=x;srlab_view_8080=two"}
    assert cookie_values(headers, "srlab_view_8080") == ["one", "two"]
    assert cookie_values({}, "srlab_view_8080") == []
