"""`/docs` in real Chromium with every request beyond the service refused, as offline.

A lab robot's machine often has no internet: the page must list the API's operations from
files the service serves itself, and ask nothing of any other host.
"""

from __future__ import annotations

from urllib.parse import urlsplit

from playwright.sync_api import Page, Route, expect

from bench.liveserver import LiveServer

METHODS = {"get", "put", "post", "delete", "patch"}


def test_docs_lists_every_operation_with_no_request_beyond_the_service(
    page: Page, server: LiveServer
) -> None:
    origin = urlsplit(server.url).netloc
    refused: list[str] = []

    def offline(route: Route) -> None:
        if urlsplit(route.request.url).netloc == origin:
            route.continue_()
        else:
            refused.append(route.request.url)
            route.abort("internetdisconnected")

    page.route("**/*", offline)
    page.goto(f"{server.url}/docs")

    create = page.locator("#operations-runs-createRun")
    expect(create).to_be_visible()
    expect(create.locator(".opblock-summary-method")).to_have_text("POST")
    expect(create.locator(".opblock-summary-path")).to_have_attribute("data-path", "/api/runs")
    paths = server.client.get("/openapi.json").json()["paths"]
    operations = sum(len(METHODS & item.keys()) for item in paths.values())
    expect(page.locator(".opblock")).to_have_count(operations)
    assert refused == []


def test_redoc_is_not_served(server: LiveServer) -> None:
    # Redoc's bundle fetches Redocly's logo from its CDN whatever the options: no page.
    assert server.client.get("/redoc").status_code == 404
