"""Pipeline: the CLI, the config schema, the stage runner with manifests, and sweeps."""
