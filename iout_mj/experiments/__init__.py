"""Experiments on top of the envs and agents: missions, evaluation, figures, energy validation,
benchmarks."""
