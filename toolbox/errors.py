"""Errors the toolbox raises on purpose.

Design rule: a toolbox function either returns a documented value (possibly an explicit
"not found" such as ``None`` or a result with ``status``) or raises `ToolboxError` with a
message naming the offending argument and what was expected. Generated programs may catch
`ToolboxError`; anything else escaping the toolbox is a bug.
"""

from __future__ import annotations

from contracts.errors import RivetError

__all__ = ["RendererUnavailableError", "ToolboxError"]


class ToolboxError(RivetError):
    """A toolbox function was called with invalid input or could not do its job."""


class RendererUnavailableError(ToolboxError):
    """No offscreen OpenGL context could be created (EGL/OSMesa missing or broken)."""
