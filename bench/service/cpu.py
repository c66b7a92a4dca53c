"""Who used the CPU: the bench, the server and the processes it started, the rest."""

from __future__ import annotations

import os
import resource
import time

from bench.procs import machine_busy_s, tree_cpu_seconds


class CpuMeter:
    """Who used the CPU from now on: the bench, the server and the rest of the machine.

    The server's share is its process's and those it started (the store's, the engines').

    The bench counts the children it waited for (wrk); other work on the machine skews
    every figure, so it is shown too.
    """

    def __init__(self, server_pid: int) -> None:
        self._pid = server_pid
        self._started = time.perf_counter()
        self._client = self._client_s()
        self._server = tree_cpu_seconds(server_pid)
        self._machine = machine_busy_s()

    @staticmethod
    def _client_s() -> float:
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.process_time() + children.ru_utime + children.ru_stime

    def client_share(self) -> float:
        """The bench's CPU since the start, as a share of one core."""
        return (self._client_s() - self._client) / (time.perf_counter() - self._started)

    def report(self, client: str = "client") -> str:
        """Each one's share of one core since the start."""
        wall = time.perf_counter() - self._started
        mine = self._client_s() - self._client
        server1, machine1 = tree_cpu_seconds(self._pid), machine_busy_s()
        parts = [f"{client} {mine / wall:.0%}"]
        server = None
        if self._server is not None and server1 is not None:
            server = server1 - self._server
            parts.append(f"server {server / wall:.0%}")
        if self._machine is not None and machine1 is not None and server is not None:
            rest = max(0.0, machine1 - self._machine - server - mine)
            parts.append(f"rest of the machine {rest / wall:.0%}")
        return f"{', '.join(parts)} of one core ({os.cpu_count()} cores)"
