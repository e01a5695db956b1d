"""The simulator application: a scenario flown through the closed loop into a recording
(:mod:`quadfault.sim.simulator`) and the ``quadfault simulate`` command
(:mod:`quadfault.sim.cli`)."""
