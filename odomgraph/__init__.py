"""odomgraph: wheel-odometry error estimation for differential-drive robots.

Library first: every CLI command is a function here.

* ``odomgraph.io``: log directories (read, write, validate), robot.toml, estimate output.
* ``odomgraph.sim``: scenarios and the simulator.
* ``odomgraph.estimators``: the EKF of Kreinar & Quinn (and the smoothers), all
  returning the same ``Estimate``.
* ``odomgraph.analysis``: metrics against truth, consistency, plots.
* ``odomgraph.pipeline`` and ``odomgraph.runs``: estimate, calibrate, compare.
"""
__version__ = "0.1.0"

#: The public API, imported on first use (``import odomgraph`` stays light):
#: ``odomgraph.read_log(DIR)``, ``odomgraph.estimate(log, "batch")``,
#: ``odomgraph.calibrate(log)``, ``odomgraph.compare(log)`` (every estimator
#: side by side), ``odomgraph.simulate(scenario, seed)``, ``odomgraph.Online(robot, "isam2")``
#: (live, one measurement at a time) with ``odomgraph.load_robot("robot.toml")``.
_API = {"read_log": "odomgraph.io.log", "write_log": "odomgraph.io.log", "estimate": "odomgraph.pipeline",
        "calibrate": "odomgraph.pipeline", "Method": "odomgraph.estimators.registry",
        "Schedule": "odomgraph.estimators.schedule", "simulate": "odomgraph.sim.simulate",
        "Estimate": "odomgraph.result", "compare": "odomgraph.runs", "Online": "odomgraph.online",
        "load_robot": "odomgraph.io.robot"}
__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        import importlib
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'odomgraph' has no attribute {name!r}")
