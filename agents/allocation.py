"""Moved: the estimate-aware allocation is part of the model, :mod:`quadfault.allocation`
(the environments use it too). This name keeps working for one release."""

import warnings

from quadfault.allocation import *  # noqa: F401,F403
from quadfault.allocation import __all__  # noqa: F401

warnings.warn("agents.allocation moved to quadfault.allocation", DeprecationWarning,
              stacklevel=2)
