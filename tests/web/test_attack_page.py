"""The attack as it was found: a page of another loopback origin, opened in real Chromium.

No token is set (loopback), so before the cross-site guard this page stopped, paused and
rewarded a running run, created a run, chose the 3D view's run and opened the view's
socket. Every one of those is refused now, and nothing is stored.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
import viser
from conftest import BROWSER_WAIT_MS
from liveharness import wait_status
from playwright.sync_api import Browser
from reliability_report import record

from bench.liveserver import LiveServer, free_port

ATTACK = """<!doctype html><html><body>
<iframe name="sink"></iframe>
<form id="form" method="post" target="sink" action="{api}/api/runs/{run}/stop"></form>
<script>
window.attack = async () => {{
  const api = "{api}", run = {run}, out = {{}};
  const send = async (path, init) => {{
    try {{
      await fetch(api + path, {{ method: "POST", mode: "no-cors", ...init }});
      return "sent";
    }} catch (e) {{
      return String(e);
    }}
  }};
  for (const action of ["stop", "pause", "view"]) {{
    out[action] = await send(`/api/runs/${{run}}/${{action}}`);
  }}
  const text = (body) => ({{
    headers: {{ "Content-Type": "text/plain" }}, body: JSON.stringify(body),
  }});
  out.reward = await send(`/api/runs/${{run}}/rewards`, text({{ value: -1 }}));
  out.create = await send("/api/runs", text({{ condition: "delayed" }}));
  out.socket = await new Promise((resolve) => {{
    const ws = new WebSocket("ws://127.0.0.1:{viser_port}/", ["viser-v{viser_version}"]);
    ws.onopen = () => {{ resolve("open"); ws.close(); }};
    ws.onerror = () => resolve("refused");
  }});
  return out;
}};
</script></body></html>"""


@pytest.fixture
def attacker(server: LiveServer) -> Iterator[tuple[str, int]]:
    """A page server on another loopback origin (localhost, its own port), and the run."""
    run = server.client.post(
        "/api/runs", json={"condition": "delayed", "mode": "realtime", "hz": 10}
    )
    run_id = int(run.json()["id"])
    server.client.post(f"/api/runs/{run_id}/start").raise_for_status()
    wait_status(server.client, run_id, "running")
    viser_port = server.client.get("/api/health").json()["viser_port"]
    page = ATTACK.format(
        api=server.url, run=run_id, viser_port=viser_port, viser_version=viser.__version__
    ).encode()

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(page)))
            self.end_headers()
            self.wfile.write(page)

        def log_message(self, format: str, *args: object) -> None:
            pass

    port = free_port()
    httpd = ThreadingHTTPServer(("127.0.0.1", port), Handler)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://localhost:{port}/", run_id
    finally:
        httpd.shutdown()
        httpd.server_close()
        server.client.post(f"/api/runs/{run_id}/stop")


def test_a_page_of_another_origin_can_change_nothing(
    browser: Browser, server: LiveServer, attacker: tuple[str, int]
) -> None:
    url, run_id = attacker
    runs_before = server.client.get("/api/runs").json()["count"]
    # Its own context: the refused socket is a console error this page is expected to show.
    context = browser.new_context()
    page = context.new_page()
    page.set_default_timeout(BROWSER_WAIT_MS)
    page.goto(url)
    outcome = page.evaluate("window.attack()")
    # no-cors requests are sent (the browser hides the answer); the socket never opens.
    assert outcome["socket"] == "refused", outcome
    with page.expect_event("requestfinished", predicate=lambda r: r.url.endswith("/stop")):
        page.evaluate("document.getElementById('form').submit()")
    form = page.frame(name="sink")
    assert form is not None
    form.wait_for_load_state()
    assert "may not change anything" in form.content()
    context.close()

    run = server.client.get(f"/api/runs/{run_id}").json()
    rewards = server.client.get(f"/api/runs/{run_id}/rewards").json()["count"]
    record(
        "a page of another origin (Chromium)",
        "from http://localhost:<other port>, no token: no-cors POSTs to stop, pause, view, "
        "reward and create, a form POST to stop, and the 3D view's websocket",
        f"run {run['status']}, {rewards} rewards stored, socket {outcome['socket']}, "
        "the form answered 403",
    )
    assert run["status"] == "running"
    assert server.client.get(f"/api/runs/{run_id}/rewards").json()["count"] == 0
    assert server.client.get("/api/runs").json()["count"] == runs_before
