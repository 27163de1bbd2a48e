"""Fitting a learned family: the training loop, budgets (steps, epochs, seconds), resumable checkpoints,
and the search spaces of the tuning study.
"""
