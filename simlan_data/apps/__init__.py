"""The entry points: run, replay, evals, view (Rerun), recover; shared command-line handling."""
