"""The estimators' settings read and checked in one place: the checks every configuration
dataclass runs in ``__post_init__`` (:class:`estimators.ekf.EKFConfig`,
:class:`estimators.ukf.UKFConfig`, :class:`estimators.rls.RLSConfig`,
:class:`estimators.irls_config.IRLSConfig`) and the reader of ``quadfault estimate``'s
options (:func:`from_options`, the registry's ``Config.from_options``).

A bad value raises :class:`quadfault.errors.ConfigError` naming the setting and the value.
"""

from __future__ import annotations

import math
from dataclasses import replace

from quadfault.errors import ConfigError


def _number(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float))


def check_positive(config, *keys: str) -> None:
    """Each setting ``keys`` of ``config`` is a finite number > 0."""
    for key in keys:
        value = getattr(config, key)
        if not (_number(value) and math.isfinite(value) and value > 0):
            raise ConfigError(
                f"{type(config).__name__}.{key} must be a positive number, got {value!r}"
            )


def check_finite(config, *keys: str) -> None:
    """Each setting ``keys`` of ``config`` is a finite number."""
    for key in keys:
        value = getattr(config, key)
        if not (_number(value) and math.isfinite(value)):
            raise ConfigError(
                f"{type(config).__name__}.{key} must be a finite number, got {value!r}"
            )


def check_fraction(config, key: str) -> None:
    """The setting ``key`` of ``config`` is a number in (0, 1] (a forgetting factor)."""
    value = getattr(config, key)
    if not (_number(value) and 0.0 < value <= 1.0):
        raise ConfigError(f"{type(config).__name__}.{key} must be in (0, 1], got {value!r}")


def check_bounds(owner: str, bounds) -> None:
    """``bounds`` is None or ``(low, high)`` with ``low < high`` (``owner``'s ``eta_bounds``)."""
    if bounds is None:
        return
    try:
        lo, hi = (float(b) for b in bounds)
    except (TypeError, ValueError):
        lo = hi = math.nan
    if not lo < hi:
        raise ConfigError(f"{owner}.eta_bounds must be (low, high) with low < high, got {bounds!r}")


def check_prefilter(owner: str, tau) -> None:
    """``tau`` is a finite number >= 0 [s] (``owner``'s ``prefilter``)."""
    if not (_number(tau) and 0.0 <= tau < math.inf):
        raise ConfigError(f"{owner}.prefilter must be a time constant >= 0 [s], got {tau!r}")


def from_options(config_class, **options):
    """The configuration ``config_class`` with the defaults replaced by the options given
    (None: the default); numbers are taken as floats, anything else is left to the
    configuration's own checks."""
    given = {
        key: float(value) if _number(value) else value
        for key, value in options.items()
        if value is not None
    }
    return replace(config_class(), **given)


__all__ = [
    "check_bounds",
    "check_finite",
    "check_fraction",
    "check_positive",
    "check_prefilter",
    "from_options",
]
