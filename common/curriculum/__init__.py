"""Curricula: the YAML schema, the stage runner, policies with their manifest, resume."""
