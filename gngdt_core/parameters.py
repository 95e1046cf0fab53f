"""Every parameter declared once: its type, range and default together, validated in one place.

scikit-learn's layout: an estimator (`GNGDT`, `GNG`, `GNGW`; the base `Estimator`, made with
`estimator`) declares each hyper-parameter as a `param` field, default, constraint and meaning in
one line; its constructor stores the values unchanged, ``fit``/``partial_fit`` validate them
(`Estimator.check_params`), and ``get_params``/``set_params`` read and change them, so
``sklearn.base.clone`` works (gngdt never imports scikit-learn). A group of settings that is not an
estimator (segmentation, frame schedule, learner options) is a frozen dataclass of `param` fields
(`Settings`), validated when made; `from_mapping` builds such a group from a TOML table. Profiles
(TOML files) only override these declarations; `gngdt.io.profiles` reads them, and `gngdt learn
--print-params` shows the effective values and where each came from.
"""

from __future__ import annotations

import inspect
import math
import numbers
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Self, TypeVar

import numpy as np

#: node budget ceiling: the adjacency alone takes ~200 bytes a node, so 10 million nodes is
#: ~2 GB; a larger budget (e.g. from a crafted checkpoint) is refused before any allocation
MAX_NODES_LIMIT = 10_000_000

_BRACKETS = {"both": "[]", "left": "[)", "right": "(]", "neither": "()"}


@dataclass(frozen=True)
class Interval:
    """A number of ``kind`` (int or float) within ``low``..``high``; ``closed`` says which ends
    belong to it ("both", "left", "right", "neither"); ``optional``: None is allowed too."""

    kind: type
    low: float = -math.inf
    high: float = math.inf
    closed: str = "both"
    optional: bool = False

    def check(self, name: str, value: Any) -> Any:
        """``value`` normalised (int or float), or ValueError naming ``name``."""
        if value is None and self.optional:
            return None
        integral = self.kind is int
        wanted = numbers.Integral if integral else numbers.Real
        if isinstance(value, bool) or not isinstance(value, wanted):
            raise ValueError(f"{name} must be {'an integer' if integral else 'a real number'}"
                             f"{' or None' if self.optional else ''}, got {value!r}")
        number = int(value) if integral else float(value)
        if not integral and not math.isfinite(number):
            raise ValueError(f"{name} must be finite, got {value!r}")
        low_ok = number > self.low or (number == self.low and self.closed in ("both", "left"))
        high_ok = number < self.high or (number == self.high and self.closed in ("both", "right"))
        if not (low_ok and high_ok):
            raise ValueError(f"{name} must be in {self.describe()}, got {value!r}")
        return number

    def describe(self) -> str:
        left, right = _BRACKETS[self.closed]
        return f"{left}{_bound(self.low)}, {_bound(self.high)}{right}"


def _bound(value: float) -> str:
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return str(int(value)) if value == int(value) else f"{value:g}"


@dataclass(frozen=True)
class Point3:
    """Three finite numbers (a point in metres), as a tuple of floats; ``optional``: or None."""

    optional: bool = False

    def check(self, name: str, value: Any) -> tuple[float, float, float] | None:
        if value is None and self.optional:
            return None
        try:
            point = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{name} must be 3 numbers or None: {error}") from error
        if point.shape != (3,) or not np.isfinite(point).all():
            raise ValueError(f"{name} must be 3 finite numbers or None, got {value!r}")
        return (float(point[0]), float(point[1]), float(point[2]))


@dataclass(frozen=True)
class OneOf:
    """A string, one of ``choices`` (empty: any non-empty string)."""

    choices: tuple[str, ...] = ()

    def check(self, name: str, value: Any) -> str:
        if not isinstance(value, str) or not value:
            raise ValueError(f"{name} must be a non-empty string, got {value!r}")
        if self.choices and value not in self.choices:
            raise ValueError(f"{name} must be one of {', '.join(self.choices)}, got {value!r}")
        return value


@dataclass(frozen=True)
class Numbers:
    """A non-empty sequence of numbers, each within ``each`` (an `Interval`), as a tuple."""

    each: Interval

    def check(self, name: str, value: Any) -> tuple:
        if isinstance(value, str) or not hasattr(value, "__len__") or len(value) == 0:
            raise ValueError(f"{name} must be a non-empty list of numbers, got {value!r}")
        return tuple(self.each.check(f"{name}[{index}]", item)
                     for index, item in enumerate(value))


@dataclass(frozen=True)
class Flag:
    """True or False."""

    def check(self, name: str, value: Any) -> bool:
        if not isinstance(value, bool | np.bool_):
            raise ValueError(f"{name} must be true or false, got {value!r}")
        return bool(value)


Constraint = Interval | Point3 | OneOf | Numbers | Flag

def param(default: Any, constraint: Constraint, doc: str = "") -> Any:
    """A dataclass field declaring one setting: default, constraint and meaning together."""
    return field(default=default, metadata={"constraint": constraint, "doc": doc})


def check_fields(instance: Any, what: str = "") -> None:
    """Check every `param` field of a dataclass ``instance``; ValueError naming the field
    (prefixed by ``what``, e.g. "learner option")."""
    for item in fields(instance):
        constraint = item.metadata.get("constraint")
        if constraint is not None:
            name = f"{what} {item.name}" if what else item.name
            constraint.check(name, getattr(instance, item.name))


def describe_fields(cls: type) -> dict[str, str]:
    """Field name -> its meaning (the ``doc`` given to `param`)."""
    return {item.name: item.metadata.get("doc", "") for item in fields(cls)}


SettingsT = TypeVar("SettingsT")


class Settings:
    """Base of a group of settings that is not an estimator: a frozen dataclass of `param`
    fields, checked when made (`check`), made from a mapping such as a TOML table by
    `from_dict`. ``WHAT`` names one of its keys in messages ("tracker parameter"); a subclass
    with checks across fields extends `check`."""

    WHAT: ClassVar[str] = "parameter"

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """ValueError naming the first field out of its constraint."""
        check_fields(self, self.WHAT)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> Self:
        """From a mapping (a TOML table); ValueError naming an unknown key."""
        return from_mapping(cls, values, cls.WHAT)


def from_mapping(cls: type[SettingsT], values: dict[str, Any], what: str) -> SettingsT:
    """``cls`` (a dataclass of `param` fields) from a mapping such as a TOML table; ValueError
    naming unknown keys (``what``: "segmentation parameter", "frame schedule key", ...)."""
    known = {item.name for item in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {what}(s) {unknown}; known: {sorted(known)}")
    return cls(**values)


class Estimator:
    """Base of the estimators, scikit-learn's layout without scikit-learn: hyper-parameters are
    `param` fields of a subclass made with `estimator`; the generated constructor stores them
    unchanged, `check_params` validates them (``fit`` and ``partial_fit`` call it), and
    `get_params`/`set_params` read and change them (``sklearn.base.clone`` uses these)."""

    #: parameter name -> its constraint, read from the fields by `estimator`
    _parameter_constraints: ClassVar[dict[str, Constraint]] = {}

    @classmethod
    def _get_param_names(cls) -> list[str]:
        """The constructor's parameter names, sorted (as scikit-learn reads them)."""
        return sorted(name for name in inspect.signature(cls.__init__).parameters
                      if name != "self")

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """Parameter name -> value as given (``deep``: there are no nested estimators)."""
        return {name: getattr(self, name) for name in self._get_param_names()}

    def set_params(self, **params: Any) -> Self:
        """Change parameters (validated at the next ``fit`` or ``partial_fit``); ValueError
        naming an unknown one."""
        valid = self._get_param_names()
        for name in params:
            if name not in valid:
                raise ValueError(f"invalid parameter {name!r} for {type(self).__name__}; "
                                 f"valid parameters: {valid}")
        for name, value in params.items():
            setattr(self, name, value)
        return self

    def check_params(self) -> dict[str, Any]:
        """Every parameter checked against its constraint and normalised (an integral float
        of an int parameter as int, a point as a tuple); ValueError naming the first that is
        out of range. Subclasses add checks across parameters."""
        return {name: constraint.check(name, getattr(self, name))
                for name, constraint in self._parameter_constraints.items()}


EstimatorT = TypeVar("EstimatorT", bound=type)


def estimator(cls: EstimatorT) -> EstimatorT:
    """Class decorator of an `Estimator` subclass: a keyword-only dataclass of its `param`
    fields (compared by identity, as estimators are), ``_parameter_constraints`` read from
    them."""
    cls = dataclass(eq=False, kw_only=True)(cls)
    cls._parameter_constraints = {item.name: item.metadata["constraint"]
                                  for item in fields(cls)}
    return cls
