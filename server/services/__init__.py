"""Application services: what the routes call when a use case is more than one port call."""
