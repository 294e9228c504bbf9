"""Simulated logs: scenarios (what happens) and the simulator (what sensors see)."""
