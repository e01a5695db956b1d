"""The environment classes (see :mod:`quad_fault_env.envs.quad_fault`)."""

from quad_fault_env.envs.quad_fault import QuadFaultEnv

__all__ = ["QuadFaultEnv"]
