"""`/docs` (Swagger UI) from the service itself, with no CDN.

FastAPI's own page loads its script and styles from cdn.jsdelivr.net, so on a machine
without the internet (a lab robot's, often) it stays blank. The fastapi-offline package
ships the files the page loads (Swagger UI's bundle and CSS, a favicon) at the versions
its release pins; they are served here under `ASSETS`, and the page is FastAPI's, pointed
at them (FastAPI's recipe for self-hosting the docs' JavaScript and CSS).

There is no `/redoc`: Redoc's bundle always fetches Redocly's logo from its CDN.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

DOCS = "/docs"
ASSETS = "/docs-assets"
FILES = Path(str(files("fastapi_offline") / "static"))
"""swagger-ui-bundle.js, swagger-ui.css and favicon.png (and Redoc's bundle, unused)."""


def install(app: FastAPI) -> None:
    """Serve the documentation page and its files on `app` (made with no docs_url)."""
    assert app.docs_url is None and app.redoc_url is None, "FastAPI's CDN pages are off"
    app.mount(ASSETS, StaticFiles(directory=FILES), name="docs-assets")

    async def swagger_ui(request: Request) -> HTMLResponse:
        root = request.scope.get("root_path", "").rstrip("/")
        return get_swagger_ui_html(
            openapi_url=f"{root}{app.openapi_url}",
            title=f"{app.title} - Swagger UI",
            swagger_js_url=f"{root}{ASSETS}/swagger-ui-bundle.js",
            swagger_css_url=f"{root}{ASSETS}/swagger-ui.css",
            swagger_favicon_url=f"{root}{ASSETS}/favicon.png",
        )

    # A plain route, as FastAPI adds its own pages: not an API operation (server.api.routing).
    app.add_route(DOCS, swagger_ui, include_in_schema=False)
