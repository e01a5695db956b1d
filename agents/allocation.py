"""Moved: the estimate-aware allocation is part of the model, :mod:`quadfault.model.allocation`
(the environments use it too). This name keeps working for one release."""

import warnings

from quadfault.model.allocation import *  # noqa: F401,F403
from quadfault.model.allocation import __all__  # noqa: F401

warnings.warn(
    "agents.allocation moved to quadfault.model.allocation", DeprecationWarning, stacklevel=2
)
