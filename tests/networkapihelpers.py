"""What the S-R editor's API tests share: a client on a fresh service, a network made, its pairs."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from apphelpers import client_for, settings_for

A = "/api/networks"


@pytest.fixture
async def client(tmp_path: Path) -> AsyncIterator[httpx.AsyncClient]:
    async with client_for(settings_for(tmp_path)) as (c, _):
        yield c


async def make(client: httpx.AsyncClient, name: str = "mine", **body: Any) -> dict[str, Any]:
    r = await client.post(A, json={"name": name, **body})
    assert r.status_code == 201, r.text
    data: dict[str, Any] = r.json()
    return data


def pairs(network: dict[str, Any]) -> dict[tuple[str, str], dict[str, Any]]:
    return {(a["stimulus"], a["behaviour"]): a for a in network["associations"]}


# --- list, create, read, delete ------------------------------------------------------
