"""srlab's adapters around the pure core: the HTTP service, storage, the 3D view, the CLI.

The rooms: `api/` (the HTTP API's routes and its contract), `services/` (live network
edits), `persistence/` (SQLAlchemy, migrations), `runtime/` (the runs'
host, where they tick, and the service's side of them), `viewer/` (the viser
3D view), `cli/` (the `srlab` command, a module a command), `reports/` (the markdown,
JSON and plots the experiment commands write) and `backends/` (where experiment tasks
run besides local processes: Ray).

At the top, the service's own wiring: `main.py` (`create_app`), `bootstrap.py` (what the
service is made of), `config.py` (settings), `schemas/` (the HTTP models, by area), `asgi.py`,
`serve.py` (uvicorn), the protections of both
ports (`guard.py`, `ratelimit.py`, `timeouts.py`) and `healthcheck.py` (the container's);
and small helpers of the service and the commands: `runspec.py` (a run's spec from a
request, a command line or a row), `probe_cache.py` (the placement probe's results on
disk), `tuning.py` (the interpreter set up for engines) and `web_enums.py` (writes the
web client's enums module from the OpenAPI document).
"""
