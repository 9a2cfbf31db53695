"""The shared scene representation: JSON Schemas, one validation entry point, SE(3).

Design rule: schemas and plain values only — no I/O beyond reading the packaged schema files,
no simulator, no Docker. Values are JSON-style dicts and lists (poses may be numpy arrays);
every boundary (sandbox output, artifact load, CLI input) calls `validate(kind, value)`.
"""

from contracts import se3
from contracts.errors import ContractError, InvalidInputError, RivetError, UsageError, user_input
from contracts.validate import SCHEMA_NAMES, format_path, is_valid, to_jsonable, validate

__all__ = [
    "SCHEMA_NAMES",
    "ContractError",
    "InvalidInputError",
    "RivetError",
    "UsageError",
    "format_path",
    "is_valid",
    "se3",
    "to_jsonable",
    "user_input",
    "validate",
]
