"""CLI sub-commands. Each module here defines ``register(app: typer.Typer) -> None``."""
