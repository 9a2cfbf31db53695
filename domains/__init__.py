"""Task domains: registry, base class, and the three simulated domains.

`domains.load(name)` gives a `Domain`; `domains.names()` lists them. Each domain package
registers itself on import (dm_control style); the built-in ones are imported here.
"""

from __future__ import annotations

from domains import assembly, cubes, tangram  # noqa: F401  (register themselves)
from domains.base import (
    BENCHMARK_GOALS,
    BENCHMARK_STARTS,
    CameraSpec,
    Domain,
    Instance,
    MeshSpec,
    ObjectSpec,
    Tolerance,
    scene_from_json,
    scene_to_json,
)
from domains.errors import DomainError, GenerationError, UnknownDomainError, UnknownObjectError
from domains.registry import load, names, register

__all__ = [
    "BENCHMARK_GOALS",
    "BENCHMARK_STARTS",
    "CameraSpec",
    "Domain",
    "DomainError",
    "GenerationError",
    "Instance",
    "MeshSpec",
    "ObjectSpec",
    "Tolerance",
    "UnknownDomainError",
    "UnknownObjectError",
    "load",
    "names",
    "register",
    "scene_from_json",
    "scene_to_json",
]
