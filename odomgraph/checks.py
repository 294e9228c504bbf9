"""Declared value ranges of option and parameter fields, checked in one place.

An options dataclass declares each field's range where the field is declared,
``keyframe_hz: float = bounded(5.0, gt=0)``, and calls ``check_fields(self)``
in ``__post_init__``. The same declarations serve the library (a bad value
raises OptionError), the CLI (whose options are these fields, so the message
names the option) and robot.toml (``io.robot`` reads ranges from here).
"""
from __future__ import annotations

import math
from dataclasses import MISSING, Field, field, fields

from odomgraph.errors import OptionError


def bounded(default=MISSING, *, gt=None, ge=None, le=None, lt=None, integer: bool = False,
            choices: tuple | None = None, optional: bool = False, infinite: bool = False,
            default_factory=MISSING) -> Field:
    """A dataclass field with a declared range (checked by ``check_fields``).

    ``optional``: None is allowed (meaning "off" or "pick by the data");
    ``infinite``: +inf is allowed (a limit that is off)."""
    meta = {"gt": gt, "ge": ge, "le": le, "lt": lt, "integer": integer, "choices": choices, "optional": optional,
            "infinite": infinite}
    if default_factory is not MISSING:
        return field(default_factory=default_factory, metadata={"range": meta})
    return field(default=default, metadata={"range": meta})


def range_text(meta: dict) -> str:
    """The declared range in words, e.g. '> 0' or 'between 0 and 1'."""
    if meta.get("gt") == 0 and not any(meta.get(k) is not None for k in ("ge", "lt", "le", "choices")):
        return "positive"
    if meta.get("ge") == 0 and not any(meta.get(k) is not None for k in ("gt", "lt", "le", "choices")):
        return "non-negative"
    lo, hi = meta.get("ge"), meta.get("le")
    if lo is not None and hi is not None and meta.get("gt") is None and meta.get("lt") is None:
        sign = "positive, " if lo > 0 else ("non-negative, " if lo == 0 else "")
        return f"{sign}between {lo:g} and {hi:g}"
    parts = []
    for key, op in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<=")):
        if meta.get(key) is not None:
            parts.append(f"{op} {meta[key]:g}")
    if meta.get("choices"):
        parts.append("one of " + ", ".join(map(str, meta["choices"])))
    return " and ".join(parts) or "a finite number"


def value_problem(value, meta: dict) -> str | None:
    """Why ``value`` breaks the range ``meta`` (see ``bounded``), or None if it is fine."""
    if value is None:
        return None if meta.get("optional") else "must be set"
    if meta.get("choices"):
        return None if value in meta["choices"] else f"must be {range_text(meta)}"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"must be a number, got {type(value).__name__}"
    if not math.isfinite(value) and not (meta.get("infinite") and value == math.inf):
        return "must be a finite number"
    if meta.get("integer") and value != int(value):
        return "must be a whole number"
    ok = ((meta.get("gt") is None or value > meta["gt"]) and (meta.get("ge") is None or value >= meta["ge"])
          and (meta.get("lt") is None or value < meta["lt"]) and (meta.get("le") is None or value <= meta["le"]))
    return None if ok else f"must be {range_text(meta)}"


def value_text(value) -> str:
    """A value as a message shows it: numbers plainly (numpy scalars print as
    np.float64(...) through repr), anything else by repr."""
    if isinstance(value, (int, float)) and not isinstance(value, bool) or hasattr(value, "dtype"):
        try:
            return f"{float(value):.6g}"
        except (TypeError, ValueError):
            pass
    return repr(value)


def option_name(name: str) -> str:
    """The CLI spelling of an options field: keyframe_hz -> --keyframe-hz."""
    return "--" + name.replace("_", "-")


def check_fields(obj) -> None:
    """Raise OptionError for the first field of dataclass ``obj`` outside its declared range."""
    for f in fields(obj):
        meta = f.metadata.get("range")
        if meta is None:
            continue
        problem = value_problem(getattr(obj, f.name), meta)
        if problem:
            raise OptionError(f"{type(obj).__name__}.{f.name} ({option_name(f.name)}) {problem}, "
                              f"got {value_text(getattr(obj, f.name))}")


def field_ranges(cls) -> dict[str, dict]:
    """{field name: declared range} of a dataclass (fields without one are left out)."""
    return {f.name: f.metadata["range"] for f in fields(cls) if "range" in f.metadata}


def unknown_names(given, known, what: str) -> str | None:
    """A message for names in ``given`` that are not ``known``, suggesting the
    nearest valid one (a typo like ``lever_armm``), or None if all are known."""
    import difflib
    bad = [g for g in given if g not in known]
    if not bad:
        return None
    g = bad[0]
    close = difflib.get_close_matches(g, list(known), n=1, cutoff=0.6)
    hint = f" (did you mean '{close[0]}'?)" if close else f" (valid: {', '.join(sorted(known))})"
    return f"unknown {what} '{g}'{hint}"
