"""The offline lab: experiments over seeds and what is made of them.

Analysis, statistics, sweeps, tuning, the studies of noise, teachers and world parameters,
and the placement probe.
"""
