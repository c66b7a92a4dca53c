"""The HTTP API: one router per resource, every route under /api (`server.api.routing`)."""

from server.api.routes import (
    catalog,
    comparisons,
    events,
    health,
    kp,
    network_history,
    networks,
    rewards,
    runs,
)

ROUTERS = tuple(
    module.router
    for module in (
        health,
        catalog,
        networks,
        network_history,
        runs,
        kp,
        comparisons,
        rewards,
        events,
    )
)
