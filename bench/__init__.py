"""Benchmarks: one script per figure the README quotes.

Beside them, what the benchmarks, the tests and scripts/ share: `browser` (Debian's
Chromium and its flags) and `liveserver` (a real `srlab serve` on loopback).
"""
