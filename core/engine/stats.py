"""The engine's pacing and storage figures, read by benchmarks and the live view."""

from __future__ import annotations

from dataclasses import dataclass, field

from core.engine.latency import LatencyHistogram


@dataclass
class EngineStats:
    """Pacing and storage figures, for benchmarks and the live view.

    The latencies are histograms (`core.engine.latency`): reading them costs the same whatever
    the run's age.
    """

    ticks: int = 0
    overruns: int = 0
    """Tick periods skipped because a tick ran past its deadline."""
    lateness_s: LatencyHistogram = field(default_factory=LatencyHistogram)
    """How late each realtime tick started after its deadline."""
    reward_commit_s: LatencyHistogram = field(default_factory=LatencyHistogram)
    """Time from applying each reward to committing its learning (queueing included)."""
    reward_ack_s: LatencyHistogram = field(default_factory=LatencyHistogram)
    """Time from a trainer's reward arriving to its acknowledgement."""
