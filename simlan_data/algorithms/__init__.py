"""gpss."""
