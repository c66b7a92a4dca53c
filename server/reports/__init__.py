"""The files the experiment commands write: markdown summaries, JSON, JSON lines and plots."""
