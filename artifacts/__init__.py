"""Frozen programs per domain (`artifacts/<domain>/`) and the thin runtime that loads them.

The runtime imports neither the model SDK nor Docker.
"""

from artifacts.errors import ArtifactError, ObservationError
from artifacts.runtime import System, load, load_modules
from artifacts.store import build_manifest, freeze, verify

__all__ = [
    "ArtifactError",
    "ObservationError",
    "System",
    "build_manifest",
    "freeze",
    "load",
    "load_modules",
    "verify",
]
