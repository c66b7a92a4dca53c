"""The cross-site guard: one rule for every state-changing request, the API's and the 3D view's.

A browser tells where a request comes from (`Origin`, `Sec-Fetch-Site`); a page of another
origin, even one on this machine's loopback, must not change anything here, token or not.
A bearer token stops a forged write only when one is configured; on loopback without one,
this is the only thing that does. Clients that are not browsers send neither header and
are not affected. The Host is checked beside it (DNS rebinding: a foreign name resolving
to loopback makes the request same-origin for the browser).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from urllib.parse import urlsplit

from starlette.types import ASGIApp, Receive, Scope, Send

from server.api.asgi import send_error

SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]", "::1")


def host_name(host: str) -> str:
    """The name of a Host header or an origin's netloc, lower-case, without its port."""
    host = host.strip().lower()
    if host.startswith("["):  # [::1]:8000
        return host[: host.find("]") + 1] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def _origin(value: str) -> str:
    """An origin as `scheme://host:port` (the port made explicit), or '' if it is none."""
    parts = urlsplit(value.strip().lower())
    if parts.scheme not in ("http", "https") or not parts.hostname:
        return ""
    port = parts.port or (443 if parts.scheme == "https" else 80)
    name = f"[{parts.hostname}]" if ":" in parts.hostname else parts.hostname
    return f"{parts.scheme}://{name}:{port}"


@dataclass(frozen=True)
class SitePolicy:
    """Which Host names this service answers to and which other origins may write to it.

    Attributes:
        hosts: accepted Host names (without port); "*" accepts any.
        origins: origins besides the request's own that may write (the editor's, for the 3D
            view; SRLAB_CORS_ORIGINS), as `scheme://host:port`.
    """

    hosts: frozenset[str]
    origins: frozenset[str]

    @classmethod
    def of(cls, hosts: Iterable[str], origins: Iterable[str]) -> SitePolicy:
        """A policy from Host names and origins as people write them."""
        names = {host_name(h) for h in hosts}
        if "[::1]" in names or "::1" in names:
            names |= {"[::1]", "::1"}
        return cls(frozenset(names), frozenset(o for o in map(_origin, origins) if o))

    def host_problem(self, host: str | None) -> str | None:
        """Why a Host header is refused, or None."""
        if "*" in self.hosts:
            return None
        if not host or host_name(host) not in self.hosts:
            return f"Host {host!r} is not a name this service answers to (SRLAB_ALLOWED_HOSTS)"
        return None

    def origin_problem(self, headers: Mapping[str, str], scheme: str) -> str | None:
        """Why a state-changing request from a browser is refused as cross-site, or None.

        Same-origin means the Origin names the very host and port the request was sent to
        (its Host header), which `host_problem` has accepted.
        """
        origin = headers.get("origin")
        site = headers.get("sec-fetch-site", "").lower()
        if origin is None:
            if site == "cross-site":
                return "a cross-site request (Sec-Fetch-Site: cross-site) may not change anything"
            return None  # not a browser, or a same-origin navigation of an old one
        own = _origin(f"{scheme}://{headers.get('host', '')}")
        given = _origin(origin)
        if given and (given == own or given in self.origins):
            return None
        return (
            f"a request from {origin} (another site) may not change anything here: "
            "open the editor this service serves, or allow that origin with SRLAB_CORS_ORIGINS"
        )


class CrossSiteGuard:
    """Answers 403 to a state-changing request (not GET, HEAD, OPTIONS) from another site."""

    def __init__(self, app: ASGIApp, policy: SitePolicy) -> None:
        self.app = app
        self.policy = policy

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Check the request's Origin before the app sees it."""
        if scope["type"] == "http" and scope["method"] not in SAFE_METHODS:
            headers = {k.decode("latin-1"): v.decode("latin-1") for k, v in scope["headers"]}
            problem = self.policy.origin_problem(headers, scope.get("scheme", "http"))
            if problem is not None:
                await send_error(send, 403, problem, [(b"vary", b"Origin")])
                return
        await self.app(scope, receive, send)
