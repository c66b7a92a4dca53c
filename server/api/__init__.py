"""The HTTP API: one router per resource, every route under /api (`server.api.routing`)."""

from server.api.routes import (
    catalog,
    comparisons,
    events,
    exports,
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
        exports,
        kp,
        comparisons,
        rewards,
        events,
    )
)
