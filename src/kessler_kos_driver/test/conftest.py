"""Shared pytest configuration for kessler_kos_driver tests.

Hypothesis settings are applied per test (see KOS_SETTINGS users), not as a global profile, so
a whole-workspace pytest run keeps other packages' settings.
"""
