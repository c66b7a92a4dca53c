"""A participant's own 3D view: a one-time ticket from the API, a cookie from the view's gate.

On a service that keeps reads to tokens (SRLAB_READS=token), with the 3D view on: a
participant's ticket opens their run's view alone, read-only; a ticket is good once, for
a minute, on its run's URL; the view refuses a socket without a good cookie, or with
another run's, before viser sees it. The organiser's ticket opens every run.
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import httpx
import pytest
from apphelpers import client_for, settings_for
from gatehelpers import becomes_viewer, page_socket, shows, until, viewer_of
from routewalk import consented_participants, study_body
from websockets.exceptions import InvalidStatus

from bench.liveserver import free_port
from server.viewer import Viewer
from server.viewer.panel import run_heading
from server.viewer.passes import TICKET_S
from server.viewer.state import GiveReward, SelectRun

pytestmark = pytest.mark.anyio

TOKEN = "organiser-s3cret"
ORGANISER = {"Authorization": f"Bearer {TOKEN}"}
STUDY = study_body("views")


@pytest.fixture(scope="module")
def anyio_backend() -> str:
    return "asyncio"


@pytest.fixture(scope="module")
async def service(
    tmp_path_factory: pytest.TempPathFactory,
) -> AsyncIterator[tuple[httpx.AsyncClient, Viewer, dict[str, Any]]]:
    """Two consented participants with a live run each; the organiser's client; the view."""
    settings = settings_for(
        tmp_path_factory.mktemp("tickets"),
        viser=True,
        viser_port=free_port(),
        reads="token",
        token=TOKEN,
    )
    async with client_for(settings, headers=ORGANISER) as (client, app):
        yield client, viewer_of(app), await consented_participants(client, STUDY, 2)


def bearer(token: str) -> dict[str, str]:
    # The organiser's client sends its own header; a participant's replaces it.
    return {"Authorization": f"Bearer {token}"}


async def ticket_url(client: httpx.AsyncClient, token: str) -> str:
    r = await client.post("/api/participant/view-ticket", headers=bearer(token))
    assert r.status_code == 200, r.text
    return str(r.json()["url"])


async def open_page(viewer: Viewer, path: str, cookie: str | None = None) -> httpx.Response:
    """The view's page as a browser asks for it (no redirect followed)."""
    headers = {} if cookie is None else {"Cookie": cookie}
    async with httpx.AsyncClient(base_url=f"http://127.0.0.1:{viewer.port}") as view:
        return await view.get(path, headers=headers)


def path_of(url: str) -> str:
    return "/" + url.split("/", 3)[3]


def cookie_of(r: httpx.Response) -> tuple[str, str]:
    """The `name=value` of the view cookie an exchange set, and the rest of its header."""
    pair, _, rest = r.headers["set-cookie"].partition(";")
    return pair, rest


async def test_a_participant_gets_a_ticket_for_their_own_run_only(
    service: tuple[httpx.AsyncClient, Viewer, dict[str, Any]],
) -> None:
    client, viewer, study = service
    one, (run_one, run_two) = study["tokens"][0], study["runs"]
    r = await client.post("/api/participant/view-ticket", headers=bearer(one))
    assert r.status_code == 200, r.text
    assert r.json()["run"] == run_one
    assert r.json()["url"].startswith(f"http://127.0.0.1:{viewer.port}/run/{run_one}?ticket=")
    # Another's run, or choosing runs for the view, is the organiser's.
    for run in (run_two, run_one):
        refused = await client.post(f"/api/runs/{run}/view", headers=bearer(one))
        assert refused.status_code == 403, refused.text
    # Without a token reads are refused here; an unknown participant's token is 401.
    async with httpx.AsyncClient(transport=client._transport, base_url=client.base_url) as anon:
        assert (await anon.post("/api/participant/view-ticket")).status_code == 401
    r = await client.post("/api/participant/view-ticket", headers=bearer("srp_nobody"))
    assert r.status_code == 401
    # Before consent there is no run to view.
    r = await client.post(f"/api/studies/{STUDY['name']}/participants", json={"count": 1})
    fresh = r.json()["data"][0]["token"]
    r = await client.post("/api/participant/view-ticket", headers=bearer(fresh))
    assert r.status_code == 409 and "consent first" in r.json()["detail"]


async def test_the_view_exchanges_a_ticket_once_for_a_cookie_of_its_run(
    service: tuple[httpx.AsyncClient, Viewer, dict[str, Any]],
) -> None:
    client, viewer, study = service
    one = study["tokens"][0]
    run_one, run_two = study["runs"]
    path = path_of(await ticket_url(client, one))
    r = await open_page(viewer, path)
    assert r.status_code == 303, r.text
    assert r.headers["location"] == f"/run/{run_one}"  # the ticket is not kept in the URL
    cookie, rest = cookie_of(r)
    assert cookie.startswith(f"srlab_view_{viewer.port}=")
    assert f"Path=/run/{run_one}" in rest and "HttpOnly" in rest and "SameSite=Strict" in rest
    # The page, with its cookie; not another run's page, nor the view of every run.
    page = await open_page(viewer, f"/run/{run_one}", cookie)
    assert page.status_code == 200 and "<html" in page.text.lower()
    other = await open_page(viewer, f"/run/{run_two}", cookie)
    assert other.status_code == 403 and f"run {run_one} only" in other.json()["detail"]
    assert (await open_page(viewer, "/", cookie)).status_code == 403
    # Used once: the same ticket again is refused, and sets no cookie.
    again = await open_page(viewer, path)
    assert again.status_code == 401 and "set-cookie" not in again.headers
    assert "used already" in again.json()["detail"]
    # Without a cookie, or with one made up, nothing (reads need a token here).
    assert (await open_page(viewer, f"/run/{run_one}")).status_code == 401
    made_up = f"srlab_view_{viewer.port}=not-a-cookie"
    assert (await open_page(viewer, f"/run/{run_one}", made_up)).status_code == 401


async def test_a_ticket_on_another_runs_url_is_refused_and_stays_good(
    service: tuple[httpx.AsyncClient, Viewer, dict[str, Any]],
) -> None:
    client, viewer, study = service
    run_one, run_two = study["runs"]
    path = path_of(await ticket_url(client, study["tokens"][0]))
    ticket = path.split("?", 1)[1]
    foreign = await open_page(viewer, f"/run/{run_two}?{ticket}")
    assert foreign.status_code == 403 and "set-cookie" not in foreign.headers
    assert f"for run {run_one} only, not run {run_two}" in foreign.json()["detail"]
    assert (await open_page(viewer, f"/?{ticket}")).status_code == 403
    assert (await open_page(viewer, path)).status_code == 303  # nothing else changed


async def test_an_expired_ticket_is_refused(
    service: tuple[httpx.AsyncClient, Viewer, dict[str, Any]],
) -> None:
    client, viewer, study = service
    path = path_of(await ticket_url(client, study["tokens"][0]))
    passes = viewer.passes
    # The passes' clock a minute on, not a wait: the ticket is past its time.
    later: Callable[[], float] = lambda: time.monotonic() + TICKET_S + 1  # noqa: E731
    passes.clock = later
    try:
        r = await open_page(viewer, path)
    finally:
        passes.clock = time.monotonic
    assert r.status_code == 401 and "expired" in r.json()["detail"]
    assert (await open_page(viewer, path)).status_code == 401  # gone for good


async def test_the_views_socket_takes_the_own_runs_cookie_alone_and_shows_it_read_only(
    service: tuple[httpx.AsyncClient, Viewer, dict[str, Any]],
) -> None:
    client, viewer, study = service
    run_one, run_two = study["runs"]
    r = await open_page(viewer, path_of(await ticket_url(client, study["tokens"][0])))
    cookie, _ = cookie_of(r)
    # Another run's socket with this cookie, and a socket without one: refused before viser.
    for path, header, status in (
        (f"/run/{run_two}", cookie, 403),
        (f"/run/{run_one}", None, 401),
        ("/", None, 401),
    ):
        with pytest.raises(InvalidStatus) as refused:
            async with page_socket(viewer, path, header):
                pass
        assert refused.value.response.status_code == status, path
    assert not viewer.sessions
    async with page_socket(viewer, f"/run/{run_one}", cookie) as socket:
        session = await becomes_viewer(viewer, socket)
        controller = session.controller
        await until(lambda: shows(session, run_one), f"run {run_one}, the participant's")
        await until(lambda: controller.state.runs, "the run list")
        assert [r.id for r in controller.state.runs] == [run_one]  # no other run listed
        assert controller.state.only == run_one and not controller.state.writable
        # A participant is not told their condition.
        await until(lambda: controller.state.live is not None, "the run's figures")
        condition = (await client.get(f"/api/runs/{run_one}")).json()["condition"]
        assert controller.state.live is not None and controller.state.live.condition == ""
        assert run_heading(controller.state).startswith(f"**Run {run_one}**: seed ")
        assert condition not in run_heading(controller.state)
        # What a crafted socket could post: another run, a reward. Neither is done.
        handled = controller.handled
        controller.post(SelectRun(run_two))
        await until(lambda: controller.handled > handled, "the selection handled")
        assert shows(session, run_one) and f"run {run_one} only" in controller.state.notice
        rewards = (await client.get(f"/api/runs/{run_one}/rewards")).json()["count"]
        controller.post(GiveReward(1.0, 1))
        await until(lambda: "not given" in controller.state.notice, "the reward refused")
        assert "read-only" in controller.state.notice
        assert (await client.get(f"/api/runs/{run_one}/rewards")).json()["count"] == rewards
    await until(lambda: not viewer.sessions, "the viewer's session to end")


async def test_the_organisers_ticket_opens_every_run_with_a_writable_panel(
    service: tuple[httpx.AsyncClient, Viewer, dict[str, Any]],
) -> None:
    client, viewer, study = service
    run_one, run_two = study["runs"]
    r = await client.post(f"/api/runs/{run_two}/view")
    assert r.status_code == 200, r.text
    exchanged = await open_page(viewer, path_of(r.json()["url"]))
    assert exchanged.status_code == 303
    assert exchanged.headers["location"] == f"/run/{run_two}"
    cookie, rest = cookie_of(exchanged)
    assert "Path=/;" in rest
    assert (await open_page(viewer, "/", cookie)).status_code == 200
    async with page_socket(viewer, f"/run/{run_one}", cookie) as socket:
        session = await becomes_viewer(viewer, socket)
        controller = session.controller
        await until(lambda: shows(session, run_one), f"run {run_one}, the URL's")
        await until(lambda: len(controller.state.runs) >= 2, "every run listed")
        assert controller.state.only is None and controller.state.writable
        await until(lambda: controller.state.live is not None, "the run's figures")
        condition = (await client.get(f"/api/runs/{run_one}")).json()["condition"]
        assert f"**Run {run_one}**: {condition}, seed " in run_heading(controller.state)
    await until(lambda: not viewer.sessions, "the viewer's session to end")
