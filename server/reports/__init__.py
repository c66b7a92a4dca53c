"""The files the experiment commands write: markdown summaries, JSON, JSON lines and plots.

`base.py` holds what every report writes alike (figures with their intervals, markdown
rows, summary.json, summary.md and runs.jsonl) and loads no matplotlib; `plots.py` sets
matplotlib up for files and holds what the plots share. The writers: `experiment.py`
(`srlab experiment`: its summary.md is `experiment_markdown.py`'s, its plots
`experiment_plots.py`'s, beside the paper's figures of `paper.py`), `sweep.py`
(`srlab sweep`), `world_check.py` and `tuning.py` (`srlab world-check --out`,
`srlab tune --out`). Nothing is imported here, so a command that only formats figures does
not load matplotlib.
"""
