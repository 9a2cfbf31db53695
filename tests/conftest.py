"""Project-wide test settings: no test can reach a real model API, and rendering is headless."""

from __future__ import annotations

import os
from pathlib import Path

# Set before anything imports MuJoCo, pyrender or the Anthropic client.
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault(
    "MENAGERIE_ROOT", str(Path(__file__).resolve().parents[2] / "shared" / "menagerie")
)
os.environ["RIVET_FORBID_MODEL_API"] = "1"
# A developer's real credentials never reach a test (and `--sandbox local` refuses to run
# beside them: `rivet.commands._options.CREDENTIAL_VARIABLES`).
for _name in ("ANTHROPIC_API_KEY", "ANTHROPIC_AUTH_TOKEN", "OPENAI_API_KEY"):
    os.environ.pop(_name, None)
