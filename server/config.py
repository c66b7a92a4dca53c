"""The service's settings, from SRLAB_* environment variables."""

from __future__ import annotations

import ipaddress
import json
import math
from typing import Annotated, Literal
from urllib.parse import urlsplit

from pydantic import Field, ValidationError, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from core.brain.memory import DEFAULT_REACTION_S, MAX_REACTION_S
from server.persistence.db import DEFAULT_DATABASE_URL


class Settings(BaseSettings):
    """Everything `create_app` needs; tests build one directly.

    Attributes:
        database_url: SQLAlchemy URL of the database.
        host: address `srlab serve` binds.
        port: port `srlab serve` binds.
        token: bearer token every write needs when the service is reachable from beyond
            this machine (`reachable_through`); it is required then.
        reads: who may read the API: ``open`` (the default), anyone who may reach it; or
            ``token``, only who may write (the organiser: the token's bearer, or anyone
            on loopback when no token is set) and participants, each their own run (a
            study's data is theirs). `/api/health` stays open to anyone either way.
        max_runs: runs that may tick at the same time; past it, starting one is refused
            with 429. The default is as many 10 Hz realtime runs, each followed and
            rewarded by its trainer, as a 2-core machine paced within the study goals
            beside other work that takes a core (128 on an idle one: docs/studies.md,
            "How far one machine goes").
        max_streams: live event streams (GET /api/runs/{id}/events) open at once, over
            every run; past it, or past `max_streams_per_run` on one run, a new stream is
            refused with 503 and `Retry-After`. Each stream costs the event loop that paces
            realtime ticks some encoding per event. The default is two per run at
            `max_runs`: a trainer's console and someone watching.
        max_streams_per_run: live event streams one run may have open at once.
        reward_rate_per_s: rewards a client may inject per second (a token bucket).
        reward_burst: how many rewards it may inject at once.
        reward_run_rate_per_s: rewards one run takes per second from all its trainers
            together (a token bucket per run, beside each trainer's).
        reward_run_burst: how many rewards one run takes at once.
        max_body_bytes: larger request bodies get 413 before they are read.
        request_timeout_s: a request's head, and then its body, must arrive within this
            (slow clients: the connection is closed, a late body gets 408).
        cors_origins: origins allowed to call the API from a browser (besides the editor
            served by the service itself).
        allowed_hosts: Host headers accepted besides loopback names and `host`.
        viser: serve the 3D view (viser) beside the API; false runs without it.
        viser_port: port of the 3D view (on `host`).
        viser_max_viewers: 3D views open at once (each has a renderer of its own, which
            the service's process pays for); past it, a new one is refused with 503 and
            `Retry-After`.
        forwarded_allow_ips: reverse proxies (addresses or networks, "*" for any) trusted to
            name the client in X-Forwarded-For and X-Forwarded-Proto; empty (the default)
            ignores those headers. Behind a proxy, this is what keeps each trainer's reward
            rate limit their own instead of one shared by everybody behind the proxy. Set,
            it makes the token required (`reachable_through`).
        engines: where the runs tick: ``local``, on the service's own event loop (quick
            to start, as tests want: `create_app`'s default), or ``process``, in a process
            of their own (`server.runtime.process`), where the ticks get a GIL and a core
            of their own and every message crosses a pipe (`srlab serve`'s default).
        service_nice: with the engines in a process, how far the service's own processes (HTTP,
            the 3D view and their store process) step back for the engines' process when
            the machine is busy: a nice increment, 0-19, applied once the engines' process
            runs (`server.runtime.tuning.step_back`). `srlab serve` makes it 10 unless the
            environment says; `create_app` alone leaves it 0 (it would renice the caller).
        reaction_window: the reaction window of the runs created, ``LO-HI`` seconds
            (``SRLAB_REACTION_WINDOW=0.2-4.0``, TAMER's): a trainer's reward with the tick
            they saw credits the ticks LO to HI seconds before it. Each run keeps the
            window it was created with.
    """

    model_config = SettingsConfigDict(env_prefix="SRLAB_", extra="ignore")

    database_url: str = DEFAULT_DATABASE_URL
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=1, le=65535)
    token: str | None = None
    reads: Literal["open", "token"] = "open"
    max_runs: int = Field(96, ge=1)
    max_streams: int = Field(192, ge=1)
    max_streams_per_run: int = Field(16, ge=1)
    reward_rate_per_s: float = Field(20.0, gt=0)
    reward_burst: int = Field(40, ge=1)
    reward_run_rate_per_s: float = Field(40.0, gt=0)
    reward_run_burst: int = Field(80, ge=1)
    max_body_bytes: int = Field(64 * 1024, ge=1024)
    request_timeout_s: float = Field(10.0, gt=0, le=600)
    cors_origins: Annotated[list[str], NoDecode] = Field(default_factory=list)
    allowed_hosts: Annotated[list[str], NoDecode] = Field(default_factory=list)
    viser: bool = True
    viser_port: int = Field(8080, ge=1, le=65535)
    viser_max_viewers: int = Field(16, ge=1)
    forwarded_allow_ips: Annotated[list[str], NoDecode] = Field(default_factory=list)
    engines: Literal["local", "process"] = "local"
    service_nice: int = Field(0, ge=0, le=19)
    reaction_window: Annotated[tuple[float, float], NoDecode] = DEFAULT_REACTION_S

    @field_validator("reaction_window", mode="before")
    @classmethod
    def _window_from_text(cls, v: object) -> object:
        """``LO-HI`` seconds, 0 <= LO <= HI <= 60."""
        if isinstance(v, str):
            lo, sep, hi = v.strip().partition("-")
            try:
                if not sep:
                    raise ValueError
                v = (float(lo), float(hi))
            except ValueError:
                raise ValueError(f"{v!r} is not a window LO-HI in seconds (e.g. 0.2-4.0)") from None
        if isinstance(v, tuple | list) and len(v) == 2:
            lo_s, hi_s = (float(x) for x in v)
            if not (0.0 <= lo_s <= hi_s <= MAX_REACTION_S and math.isfinite(hi_s)):
                raise ValueError(
                    f"a reaction window LO-HI needs 0 <= LO <= HI <= {MAX_REACTION_S:g} "
                    f"seconds, not {lo_s:g}-{hi_s:g}"
                )
            return (lo_s, hi_s)
        return v

    @field_validator("cors_origins", "allowed_hosts", "forwarded_allow_ips", mode="before")
    @classmethod
    def _list_from_text(cls, v: object) -> object:
        """A list from the environment: JSON (`["a", "b"]`) or comma-separated (`a,b`)."""
        if not isinstance(v, str):
            return v
        if v.lstrip().startswith("["):
            try:
                return json.loads(v)
            except json.JSONDecodeError as e:
                raise ValueError(f"not a JSON list: {e}") from None
        return [item.strip() for item in v.split(",") if item.strip()]

    @field_validator("token")
    @classmethod
    def _no_empty_token(cls, v: str | None) -> str | None:
        return v or None

    @field_validator("forwarded_allow_ips")
    @classmethod
    def _proxies_are_addresses(cls, v: list[str]) -> list[str]:
        for entry in v:
            if entry == "*":
                continue
            try:
                ipaddress.ip_network(entry)
            except ValueError:
                raise ValueError(
                    f"{entry!r} is not an IP address or network (e.g. 10.0.0.5, 10.0.0.0/24, *)"
                ) from None
        return v

    @classmethod
    def load(cls, **overrides: object) -> Settings:
        """The settings from the environment and `overrides` (command-line options).

        Raises:
            ValueError: one line per bad setting, naming its variable, e.g.
                ``SRLAB_PORT: must be >= 1, got 0``.
        """
        try:
            return cls(**overrides)  # type: ignore[arg-type]
        except ValidationError as e:
            raise ValueError(settings_problems(e)) from None

    @property
    def loopback(self) -> bool:
        """Whether the service listens on loopback only."""
        if self.host in ("localhost",):
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False

    def host_names(self) -> set[str]:
        """The Host names the API and the 3D view answer to ("*": any)."""
        if self.host in ("0.0.0.0", "::") and not self.allowed_hosts:
            return {"*"}  # every interface: the names it is reached by are unknown
        return {"127.0.0.1", "localhost", "[::1]", self.host, *self.allowed_hosts}

    def editor_origins(self) -> list[str]:
        """The origins the editor is served from, and the extra ones allowed to write."""
        names = sorted(h for h in self.host_names() if h != "*")
        return [*(f"http://{h}:{self.port}" for h in names), *self.cors_origins]

    def reachable_through(self) -> list[str]:
        """Why the service is reachable from beyond this machine, one phrase a setting.

        Empty: from this machine only. Listening beyond loopback is one way. Trusting a
        proxy is another, even a proxy on this machine: it forwards clients from elsewhere
        (that is why it is trusted to name them). A Host name that is not loopback's is
        one: requests that name it come through a proxy or DNS from elsewhere. So is a
        CORS origin on another host: its pages come from elsewhere, and whoever serves
        them (or injects a script into them) could write here through any browser on this
        machine that opens one. With the token, such a write needs a secret a person
        hands over, not just a page from the right place.
        """
        why = []
        if not self.loopback:
            why.append(f"it listens on {self.host} (SRLAB_HOST)")
        if self.forwarded_allow_ips:
            why.append("SRLAB_FORWARDED_ALLOW_IPS trusts a proxy to forward clients")
        names = [h for h in self.allowed_hosts if not loopback_name(h)]
        if names:
            why.append(f"SRLAB_ALLOWED_HOSTS names {', '.join(names)}")
        origins = [o for o in self.cors_origins if not loopback_name(urlsplit(o).hostname or o)]
        if origins:
            why.append(f"SRLAB_CORS_ORIGINS lets pages of {', '.join(origins)} write")
        return why

    @property
    def writes_need_token(self) -> bool:
        """Writes need the bearer token: reachable from beyond this machine, or a token set."""
        return bool(self.reachable_through()) or self.token is not None

    def check(self) -> None:
        """Refuse what cannot be served safely.

        Beyond this machine without a token, or two servers on one port.
        """
        if self.viser and self.viser_port == self.port:
            raise ValueError(
                f"SRLAB_VISER_PORT and SRLAB_PORT are both {self.port}: the 3D view needs a "
                "port of its own"
            )
        why = self.reachable_through()
        if why and not self.token:
            raise ValueError(
                f"srlab is reachable from beyond this machine ({'; '.join(why)}): set "
                "SRLAB_TOKEN so that writes (rewards, edits, run control) need "
                "`Authorization: Bearer <token>`"
            )


def loopback_name(name: str) -> bool:
    """Whether a host name or address can only mean this machine (``[::1]`` too)."""
    bare = name.strip().lower().removeprefix("[").removesuffix("]")
    if bare == "localhost":
        return True
    try:
        return ipaddress.ip_address(bare).is_loopback
    except ValueError:
        return False


def settings_problems(error: ValidationError) -> str:
    """A pydantic error about settings, for people: one line per variable."""
    lines = []
    for problem in error.errors():
        name = "SRLAB_" + "_".join(str(part) for part in problem["loc"][:1]).upper()
        message = problem["msg"].removeprefix("Value error, ")
        given = problem.get("input")
        got = f", got {given!r}" if given is not None and not isinstance(given, dict) else ""
        lines.append(f"{name}: {message}{got}")
    return "\n".join(lines)
