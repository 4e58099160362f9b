"""Shared core of the navigation curriculum: kinematics, scenarios, observations, rewards, controllers,
planners, evaluation. The ``curriculum`` application (runner, sweeps, bench, CLI) is :mod:`common.curriculum`."""

__version__ = "0.1.0"
