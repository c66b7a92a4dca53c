"""The HTTP service under load: tick pacing, reward acknowledgement and GET throughput.

Run as ``.venv/bin/python -m bench.service`` (about 3.5 minutes; ``--seconds 10
--seconds-get 5`` for a quick check). It starts ``srlab serve`` itself on 127.0.0.1 (a free
port, a temporary SQLite database, the reward rate limit raised so that the load generator
is not refused), waits for /api/health, runs a short uncounted realtime run (the process's
first run pays one-off costs), and measures in one run:

1. a realtime ``rp`` run at 20 Hz for ``--seconds`` (default 60) with no load, then another
   one while an open-loop load generator sends 200 requests/s of mixed traffic (60% reads,
   20% association edits on a network made for the bench, 20% rewards to the running run;
   ``--mix`` changes the shares): tick lateness p99 and max and overruns from each run's
   live figures side by side, the requests sent and their errors, latency by request kind
   and over time, and the client-side reward acknowledgement latency (goals: lateness p99
   <= 5 ms, max <= 25 ms, 0 overruns, 0 errors, ack p99 <= 20 ms);
2. GET /api/runs/{id} of a live realtime run at 1,000 requests/s for ``--seconds-get``
   (default 20), open loop: achieved requests/s, p50/p99 latency, errors, the client's own
   CPU (goal: >= 1,000 req/s at p99 <= 10 ms); then ``wrk`` (closed loop, as fast as the
   server answers) as a second measurement when it is installed.

With ``--part day`` (or by default after 1-2) it starts a second server and measures a long
day's bounds, each side by side in that run:

D1. GET /api/runs/{id} of a realtime run ``--old-ticks`` (200,000) ticks old, aged at
   1000 Hz, alternating with a fresh one's: p99 old / fresh (goal: <= 1.5);
D2. a run with ``--episodes`` (10,000) stored episodes (one real episode's row copied,
   written before the server starts): GET .../episodes?limit=50 and .../episodes/{n}
   (goal: p99 <= 20 ms), and a missing episode's 404s;
D3. ``--streams`` (500) clients of a 20 Hz run's event stream: how many are refused (503),
   and the run's overruns while the accepted ones read (goal: 0);
D4. ``--runs`` (32) realtime runs at 20 Hz under ``--rate`` req/s of mixed load spread over
   them for ``--seconds``: tick lateness p99 and max (worst run) and overruns over all runs
   (goals: <= 5 ms, <= 25 ms, 0).

With ``--part engines`` it measures D3 and D4 with the engines on the service's loop
(``SRLAB_ENGINES=local``) and in a process of their own (``SRLAB_ENGINES=process``,
`server/runtime/process.py`), a fresh server for each, alternated ``--rounds`` times,
and prints them side by side (medians over the rounds). ``--part costs`` measures what a
request of each kind in D4's mix costs the server in CPU, one at a time, and what the mix
at ``--rate`` would cost it in cores. ``--engines`` picks the placement of every other
part's servers (default: the engines' process, as ``srlab serve``).

Open loop: every request has a scheduled send time on a fixed-rate grid, whether earlier
ones were answered or not, and its latency counts from that time; a slow answer cannot hide
the requests that would have queued behind it (no coordinated omission). A request not
answered within ``--timeout`` of leaving (waiting for a free connection included) counts
as an error. The client is a small HTTP/1.1 keep-alive client on asyncio streams: on two
cores httpx.AsyncClient (``--client httpx``) cannot send 1,000 requests/s itself. CPU
shares of the client, the server and the rest of the machine are printed with each load,
since other work on the machine skews every figure.
"""

from __future__ import annotations

from bench.service.clients import HOST, Client, HttpxClient, RawClient
from bench.service.day import store_episodes
from bench.service.harness import Server, call, start_run, stop_run, wait_healthy
from bench.service.load import Load, Mix, Request, open_loop

__all__ = [
    "HOST",
    "Client",
    "HttpxClient",
    "Load",
    "Mix",
    "RawClient",
    "Request",
    "Server",
    "call",
    "open_loop",
    "start_run",
    "stop_run",
    "store_episodes",
    "wait_healthy",
]
