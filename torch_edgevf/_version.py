"""The package version, written once (read by pyproject.toml and the operator cache)."""

__version__ = "0.1.0"
