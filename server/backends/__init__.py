"""Where experiment tasks run besides this machine's processes: a Ray cluster.

The core's pure task functions (`core.experiment.run_task`) run anywhere that has the
code. `core.experiment.Backend` is the protocol; the local process pool,
`core.experiment.LocalBackend`, stays in the core because the core's own
`run_experiment`, `tune` and `world_check` run on it when given no backend. This room
holds the backends that need more than the standard library: `RayBackend`
(the optional `srlab[ray]`).
"""

from server.backends.ray import BackendError, RayBackend, check_reachable

__all__ = ["BackendError", "RayBackend", "check_reachable"]
