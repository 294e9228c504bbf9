"""``python -m odomgraph``: the command line (odomgraph.cli)."""
from odomgraph.cli import main

main()
