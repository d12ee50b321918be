"""LiveScene workflow stages: one package per stage, each with a CLI."""
