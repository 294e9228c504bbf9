"""The measurement and motion models of odomgraph, as pure numpy functions.

Every model returns ``(prediction, jacobian)`` and broadcasts over leading
array dimensions, so the same function serves

* the EKF (one state at a time),
* the vectorised Monte-Carlo EKF (many runs at once), and
* the factor-graph smoother (every factor of a graph linearised in one call).

Jacobian columns follow the order of the function's arguments, listed in each
module's ``INPUTS`` tuple. Frames and units follow ``LOG_FORMAT.md``: world x
east / y north, robot x forward / y left, SI units, heading counter-clockwise
from world x.

Equation numbers cite Kreinar & Quinn, "Odometry Error Estimation for a
Differential Drive Robot Snowplow" (the paper). The OCR of the paper garbles
several equations; each module re-derives its model and the tests check every
Jacobian numerically.
"""
