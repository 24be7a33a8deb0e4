"""Helpers shared by the test modules (statistical tests on the sphere)."""
