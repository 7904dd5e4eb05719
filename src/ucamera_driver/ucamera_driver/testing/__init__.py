"""Tool code the registry names for tests, the soak, the bench and the demo: never imported by
the runtime modules of this package."""
