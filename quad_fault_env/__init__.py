"""Gymnasium environments for fault-tolerant quadrotor control (placeholder; see issue 4)."""
