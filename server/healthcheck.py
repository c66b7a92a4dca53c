"""`python -m server.healthcheck`: exit 0 if the local service is healthy, else 1.

The container's HEALTHCHECK runs it, since the slim image has no curl. It asks
`/api/health` on 127.0.0.1 at `SRLAB_PORT` (8000 by default) and needs status "ok".
That answer also means the database answered, because the route runs `select 1`. Only the
standard library is used here: it starts in a fraction of the time the service takes, and
it works without the dev dependencies the image leaves out.
"""

from __future__ import annotations

import json
import os
import sys
import urllib.error
import urllib.request

TIMEOUT_S = 4.0
"""Less than the HEALTHCHECK's own timeout (5 s), so a slow answer is reported, not killed."""


def problem(port: int, timeout_s: float = TIMEOUT_S) -> str | None:
    """Why the service on 127.0.0.1:`port` is not healthy, or None when it is."""
    url = f"http://127.0.0.1:{port}/api/health"
    # No proxy: an HTTP(S)_PROXY in the container's environment must not reroute loopback.
    opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    try:
        with opener.open(url, timeout=timeout_s) as response:
            body = json.loads(response.read())
    except urllib.error.HTTPError as e:
        return f"{url} answered {e.code}"
    except (OSError, ValueError) as e:
        return f"{url}: {e}"
    if not isinstance(body, dict) or body.get("status") != "ok":
        return f"{url} answered {body!r}"
    return None


def main() -> int:
    """Check the service on `SRLAB_PORT`; say why on stderr when it is unhealthy."""
    port = int(os.environ.get("SRLAB_PORT") or 8000)
    why = problem(port)
    if why is None:
        return 0
    sys.stderr.write(f"srlab unhealthy: {why}\n")
    return 1


if __name__ == "__main__":
    raise SystemExit(main())
