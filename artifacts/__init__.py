"""Frozen programs per domain (`artifacts/<domain>/`) and the thin runtime that runs them in a
sandbox session (`artifacts.runtime`), the observation folders it reads
(`artifacts.observations`), the policy the trials run (`artifacts.policy`), and the
append-only JSON-lines files of journals and trial logs (`artifacts.jsonl`).

The runtime imports neither the model SDK nor the simulator.
"""

from artifacts.errors import ArtifactError, ObservationError, ProgramFailed
from artifacts.runtime import Runner, System, from_folder, load
from artifacts.store import build_manifest, freeze, unchecked_note, verify

__all__ = [
    "ArtifactError",
    "ObservationError",
    "ProgramFailed",
    "Runner",
    "System",
    "build_manifest",
    "freeze",
    "from_folder",
    "load",
    "unchecked_note",
    "verify",
]
