"""srlab's adapters around the pure core: the HTTP service, storage, the 3D view, the CLI.

The rooms: `api/` (the HTTP API's routes and its contract), `services/` (live network
edits), `persistence/` (SQLAlchemy, migrations), `runtime/` (the runs'
host, where they tick, and the service's side of them), `viewer/` (the viser
3D view), `cli/` (the `srlab` command, a module a command), `reports/` (the markdown,
JSON and plots the experiment commands write), `backends/` (where experiment tasks
run besides local processes: Ray) and `robots/` (a world over a real robot's ROS 2 topics).

At the top, only the service's entry points and wiring: `main.py` (`create_app`),
`bootstrap.py` (what the service is made of), `config.py` (settings), `serve.py` (uvicorn)
and `healthcheck.py` (the container's, kept light). The HTTP models are in `schemas/` (with
`web_enums.py`, which writes the web client's enums module from the OpenAPI document); the
protections of both ports (`guard.py`, `ratelimit.py`, `timeouts.py`) and the ASGI helpers
in `api/`; a run's spec from a request, a command line or a row (`runspec.py`) and the
placement probe's cache on disk in `services/`; the interpreter's set-up for engines
(`tuning.py`) in `runtime/`.
"""
