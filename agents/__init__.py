"""Agents: geometric and estimate-aware controllers, stable-baselines3 training (issue 5)."""
