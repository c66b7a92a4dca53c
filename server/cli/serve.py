"""`srlab serve`: the HTTP API, the editor and the 3D view (the service is `server.serve`)."""

from __future__ import annotations

import argparse
from typing import IO


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `serve` command and its arguments."""
    serve = sub.add_parser(
        "serve",
        help="serve the HTTP API and the editor (migrates the database first)",
        description="Serve the HTTP API, the S-R editor and trainer console with uvicorn "
        "(one worker). Settings come from SRLAB_* environment variables. SRLAB_TOKEN is "
        "required when the service is reachable from beyond this machine: a SRLAB_HOST "
        "beyond loopback, a trusted proxy (SRLAB_FORWARDED_ALLOW_IPS), or host names "
        "(SRLAB_ALLOWED_HOSTS) or origins (SRLAB_CORS_ORIGINS) other than loopback's.",
    )
    serve.add_argument("--host", help="address to bind (default SRLAB_HOST or 127.0.0.1)")
    serve.add_argument("--port", type=int, help="port (default SRLAB_PORT or 8000)")
    serve.set_defaults(handler=command)


def command(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Serve until interrupted; uvicorn and the app are imported for this command alone."""
    from server.serve import serve

    return serve(args.host, args.port)
