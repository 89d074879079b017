"""The run's configuration: Hydra structured-config schemas, loading and validation."""
