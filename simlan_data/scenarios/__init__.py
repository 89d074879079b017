"""Scenario generators: config values computed from a scenario's parameters (pure, no simulator)."""
