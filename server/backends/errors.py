"""The one error every backend raises: it cannot be used (its extra missing, its cluster down).

Kept apart from the backends themselves so that the CLI can catch it without importing
them (a backend imports the core's experiment code, and Ray when it runs).
"""


class BackendError(Exception):
    """The backend cannot be used (Ray missing, the cluster unreachable)."""
