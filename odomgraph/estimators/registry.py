"""The one table of estimators: each method's name, options type and run function.

``pipeline.estimate``, the comparison, the Monte-Carlo study and the CLI all
dispatch through it. A method is a ``Method`` or its name; options are the
fields of the method's options dataclass, and a name that no estimator takes
is an OptionError that lists the valid ones.

    run(log, "batch", Schedule(20.0), None, {"keyframe_hz": 2.0})
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass
from enum import Enum

import numpy as np


class Method(str, Enum):
    ekf = "ekf"
    """The paper's velocity-augmented EKF."""
    batch = "batch"
    """Factor-graph smoother, Gauss-Newton over the whole log (GTSAM elimination)."""
    isam2 = "isam2"
    """Factor-graph smoother, one gtsam.ISAM2 update per keyframe."""
    fixed_lag = "fixed-lag"
    """Factor-graph smoother, gtsam.IncrementalFixedLagSmoother."""


@dataclass(frozen=True)
class Entry:
    """Where a method lives: ``module``'s ``options`` dataclass and ``run``
    function ``run(log, schedule, options, progress) -> Estimate``. Imported
    on first use, so that importing the registry does not load GTSAM."""
    module: str
    options: str
    run: str

    def options_type(self) -> type:
        return getattr(importlib.import_module(self.module), self.options)

    def run_function(self):
        return getattr(importlib.import_module(self.module), self.run)


REGISTRY: dict[Method, Entry] = {
    Method.ekf: Entry("odomgraph.estimators.ekf", "EKFOptions", "run_ekf"),
    Method.batch: Entry("odomgraph.estimators.batch", "SmootherOptions", "run_batch"),
    Method.isam2: Entry("odomgraph.estimators.incremental", "IncrementalOptions", "run_isam2"),
    Method.fixed_lag: Entry("odomgraph.estimators.incremental", "IncrementalOptions", "run_fixed_lag"),
}


def parse_method(method) -> Method:
    """A Method from itself or its name; OptionError listing the valid ones otherwise."""
    from odomgraph.errors import OptionError
    try:
        return Method(method.value if isinstance(method, Enum) else method)
    except ValueError:
        raise OptionError(f"unknown method {method!r}; valid: {', '.join(m.value for m in Method)}") from None


def option_types() -> list[type]:
    """Every estimator's options dataclass, each once."""
    out: list[type] = []
    for e in REGISTRY.values():
        if (t := e.options_type()) not in out:
            out.append(t)
    return out


def check_option_names(options: dict) -> None:
    """Every option must belong to some estimator's options (a typo is an error,
    not a default), and lie in its declared range even where this method does
    not use it (the CLI passes one set to every method)."""
    from odomgraph.checks import field_ranges, option_name, unknown_names, value_problem, value_text
    from odomgraph.errors import OptionError
    types = option_types()
    known = {name for t in types for name in t.__dataclass_fields__}
    msg = unknown_names(list(options), known, "option")
    if msg:
        raise OptionError(msg)
    ranges: dict = {}
    for t in types:
        ranges |= field_ranges(t)
    for k, v in options.items():
        if v is not None and k in ranges and (problem := value_problem(v, ranges[k])):
            raise OptionError(f"{k} ({option_name(k)}) {problem}, got {value_text(v)}")


def foreign(method) -> set[str]:
    """The option names that other estimators' options types take and
    ``method``'s does not (the comparison leaves these out of its options)."""
    method = parse_method(method)
    own = REGISTRY[method].options_type().__dataclass_fields__
    return {k for t in option_types() for k in t.__dataclass_fields__} - set(own)


def _is_default(value, field) -> bool:
    """Whether ``value`` equals the dataclass ``field``'s default (or what its
    default_factory makes; a field without either has no default to equal).
    Arrays compare by value, not by ``==``'s element-wise truth."""
    from dataclasses import MISSING
    if field.default is not MISSING:
        default = field.default
    elif field.default_factory is not MISSING:
        default = field.default_factory()
    else:
        return False
    if isinstance(value, np.ndarray) or isinstance(default, np.ndarray):
        return np.shape(value) == np.shape(default) and bool(np.array_equal(value, default))
    return bool(value == default)


def options_for(method, options: dict) -> dict:
    """The ``options`` that ``method``'s options type takes (None values: the
    default, left out). An option only other estimators take, set to anything
    but its default there, is an OptionError naming whose it is
    (``slip_step_k`` for isam2 was dropped in silence: an option that does
    nothing must not look as if it did)."""
    from odomgraph.checks import option_name
    from odomgraph.errors import OptionError
    method = parse_method(method)
    other = foreign(method)
    for k, v in options.items():
        if v is None or k not in other:
            continue
        takers = [m for m, e in REGISTRY.items() if k in e.options_type().__dataclass_fields__]
        if not _is_default(v, REGISTRY[takers[0]].options_type().__dataclass_fields__[k]):
            raise OptionError(f"{k} ({option_name(k)}) is an option of {', '.join(m.value for m in takers)}, "
                              f"not of {method.value}")
    own = REGISTRY[method].options_type().__dataclass_fields__
    return {k: v for k, v in options.items() if k in own and v is not None}


def run(log, method, schedule, progress, options: dict):
    """Run ``method`` over ``log`` with the ``options`` its options type takes
    (options_for: the CLI passes one set for every method, None values mean
    the default; another estimator's option set to anything but its default
    is an OptionError)."""
    from odomgraph.errors import OdomgraphError
    method = parse_method(method)
    if method is Method.ekf and schedule.calibrate_until is None:
        raise OdomgraphError("the EKF needs a schedule: --calibrate-until none (slip and scale together) "
                             "is for the smoothers; use a number of seconds (0 = slip only)")
    entry = REGISTRY[method]
    opts = entry.options_type()(**options_for(method, options))
    return entry.run_function()(log, schedule, opts, progress)
