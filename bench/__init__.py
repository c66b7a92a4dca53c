"""Benchmarks: one script per figure the README quotes."""
