"""Task domains: registry, base class, and the three simulated domains.

`domains.load(name)` gives a `Domain`; `domains.names()` lists them. Each domain package
registers itself on import (dm_control style); the built-in ones are imported here.
"""

from __future__ import annotations

from domains import assembly, cubes, tangram  # noqa: F401  (register themselves)
from domains.base import Domain
from domains.benchmark import BENCHMARK_GOALS, BENCHMARK_STARTS
from domains.catalogue import CameraSpec, MeshSpec, ObjectSpec, Tolerance
from domains.errors import DomainError, GenerationError, UnknownDomainError, UnknownObjectError
from domains.generation import PhysicsCheck, Problem, geometric_problems
from domains.instance import Instance, scene_from_json, scene_to_json
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
    "PhysicsCheck",
    "Problem",
    "Tolerance",
    "UnknownDomainError",
    "UnknownObjectError",
    "geometric_problems",
    "load",
    "names",
    "register",
    "scene_from_json",
    "scene_to_json",
]
