"""Benchmarks: one script per figure the README quotes.

Beside them, what the benchmarks, the tests and scripts/ share: `browser` (Debian's
Chromium and its flags), `liveserver` (a real `srlab serve` on loopback, started and
stopped), `procs` (processes under /proc), `busy` (spinning processes) and `figures`.
What only the tests need of a live server is in tests/liveharness.py.
"""
