"""Metrics against truth, consistency, plots and reports (no estimation here)."""
