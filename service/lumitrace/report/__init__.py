"""Convergence reports: closed-form references, image metrics, error against time."""
