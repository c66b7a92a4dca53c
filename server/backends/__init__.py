"""Where experiment tasks run besides this machine's processes: a Ray cluster.

The core's pure task functions (`core.lab.experiment.run_task`) run anywhere that has the
code. `core.lab.experiment.Backend` is the protocol; the local process pool,
`core.lab.experiment.LocalBackend`, stays in the core because the core's own
`run_experiment`, `tune` and `world_check` run on it when given no backend. This room
holds the backends that need more than the standard library: `RayBackend`
(the optional `srlab[ray]`, in `server.backends.ray`).

A backend is imported where it is used: the package itself holds only `BackendError`, so
that catching it costs a command nothing.
"""

from server.backends.errors import BackendError

__all__ = ["BackendError"]
