"""Stored networks and their associations: the DP S-R editor's operations."""

from __future__ import annotations

from fastapi import APIRouter

router = APIRouter(prefix="/networks", tags=["networks"])
