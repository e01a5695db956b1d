"""quadfault: fault-tolerant quadrotor research toolkit.

The core model lives in this package and imports neither the estimators nor the
Gymnasium environment:

* :mod:`quadfault.jit`         -- the one compile decorator (numba) and its cache
* :mod:`quadfault.model.rotation`    -- SO(3) / quaternion helpers: kernels and array forms
* :mod:`quadfault.model.vehicle`     -- vehicle parameters and thrust allocation
* :mod:`quadfault.model.dynamics`    -- rigid-body dynamics and integrators (paper eqs. 1-4)
* :mod:`quadfault.model.motors`      -- motor efficiency, thrust noise, saturation (eqs. 11, 13)
* :mod:`quadfault.model.sensors`     -- measurement noise on the state and the accelerometer
* :mod:`quadfault.model.scenarios`   -- efficiency schedules and named scenarios
* :mod:`quadfault.model.trajectory`  -- reference trajectories
* :mod:`quadfault.model.controller`  -- geometric SE(3) tracking controller (eqs. 5-10)
* :mod:`quadfault.model.plant`       -- the true vehicle(s): parameters, state, the effects hook
* :mod:`quadfault.model.closed_loop` -- the one closed loop (simulator, environments, agents)
* :mod:`quadfault.sim.simulator`   -- ``simulate``: a scenario through the loop into a recording
* :mod:`quadfault.io.recording`   -- the ``quadfault-recording/1`` file format

Heavy modules are imported lazily so ``quadfault --help`` stays instant.
"""

__version__ = "0.1.0"

from quadfault.errors import QuadfaultError, RecordingError  # noqa: E402  (light, no numpy)
from quadfault.jit import configure_cache as _configure_numba_cache  # noqa: E402  (no numba yet)

_configure_numba_cache()  # before any compiled module: one numba cache per source version

__all__ = ["__version__", "QuadfaultError", "RecordingError"]

from quadfault._moved import install as _install_moved  # noqa: E402  (old import paths)

_install_moved()
