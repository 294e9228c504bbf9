"""Estimators. Each takes a Log and a Schedule and returns an ``Estimate``;
none of them prints, plots or parses arguments."""
