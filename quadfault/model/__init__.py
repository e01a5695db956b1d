"""The quadrotor model: one description of the vehicle shared by the simulator, the
estimators, the environments and the diagnosis.

Lowest first: rotations, the vehicle and its frames, trajectories; the effect library
(:mod:`quadfault.model.effects`); the rigid-body dynamics, motors, sensors and the geometric
controller; the plant, the one closed loop and the :class:`~quadfault.model.flight.Flight`
façade over it; thrust allocation and the scenarios that drive a flight.
"""
