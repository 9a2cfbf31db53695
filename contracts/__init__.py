"""The shared scene representation: typed values, JSON Schemas, one validation entry point.

Design rule: types and schemas only — no I/O beyond reading the packaged schema files, no
simulator, no Docker. Every boundary (sandbox output, artifact load, CLI input) calls
`validate(kind, value)`.
"""

from contracts import se3
from contracts.errors import ContractError, RivetError, UsageError
from contracts.types import (
    Camera,
    Edge,
    InfeasiblePlan,
    Instance,
    ObjectRecord,
    ObservationMeta,
    OkPlan,
    Plan,
    PlanStep,
    RelationGraph,
    SceneSpec,
    State,
    plan_from_dict,
    records_from_list,
    records_to_list,
)
from contracts.validate import SCHEMA_NAMES, format_path, is_valid, to_jsonable, validate

__all__ = [
    "SCHEMA_NAMES",
    "Camera",
    "ContractError",
    "Edge",
    "InfeasiblePlan",
    "Instance",
    "ObjectRecord",
    "ObservationMeta",
    "OkPlan",
    "Plan",
    "PlanStep",
    "RelationGraph",
    "RivetError",
    "SceneSpec",
    "State",
    "UsageError",
    "format_path",
    "is_valid",
    "plan_from_dict",
    "records_from_list",
    "records_to_list",
    "se3",
    "to_jsonable",
    "validate",
]
