"""srlab adapters: the command line, and later the HTTP service, persistence and 3D view."""
