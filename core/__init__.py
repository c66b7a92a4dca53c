"""srlab core: the behaviour-based architecture and its simulated world, pure and deterministic."""
