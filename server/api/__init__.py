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
    studies,
)

ROUTERS = (
    *(
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
            studies,
        )
    ),
    studies.participant_router,
    exports.study_router,
)
