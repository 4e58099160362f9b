"""Shared core of the navigation curriculum: kinematics, scenarios, observations, rewards, CLI."""

__version__ = "0.1.0"
