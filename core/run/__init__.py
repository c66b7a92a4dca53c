"""A run's domain: the simulation of a world and a brain, and what a run is set in.

The conditions it learns under, its setup, trainer, checkpoints and traces, and headless runs.
"""
