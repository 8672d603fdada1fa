"""Gear models, one module per seed system."""
