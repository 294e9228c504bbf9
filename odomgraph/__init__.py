"""odomgraph: wheel-odometry error estimation for differential-drive robots.

Library first: every CLI command is a function here.

* ``odomgraph.io``: log directories (read, write, validate), robot.toml, estimate output.
* ``odomgraph.sim``: scenarios and the simulator.
* ``odomgraph.estimators``: the EKF of Kreinar & Quinn (and the smoothers), all
  returning the same ``Estimate``.
* ``odomgraph.analysis``: metrics against truth, consistency, plots.
"""
__version__ = "0.1.0"
