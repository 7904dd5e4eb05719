"""Kessler kOS network motion-control driver (CineShooter, Second Shooter)."""
