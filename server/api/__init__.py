"""The HTTP API: one router per resource under /api."""

from fastapi import APIRouter

from server.api.errors import ERRORS
from server.api.routes import catalog, comparisons, events, health, kp, networks, rewards, runs

api_router = APIRouter(prefix="/api")
for module in (health, catalog, networks, runs, kp, comparisons, rewards, events):
    api_router.include_router(module.router, responses=ERRORS)
