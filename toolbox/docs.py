"""The toolbox documentation that goes into model prompts, built from the public docstrings.

Design rule: the docstrings are the documentation; this module only orders and formats them
(Markdown: one section per module, then each public name's signature and docstring), so the
text cannot drift from the code. Output is deterministic (no memory addresses).
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Sequence

from toolbox.errors import ToolboxError

__all__ = ["MODULES", "toolbox_docs"]

# Prompt order: basics first, then perception, then reasoning.
MODULES = (
    "geometry",
    "vision",
    "segmentation",
    "polygons",
    "registration",
    "render",
    "refine",
    "stability",
    "robot",
    "packing",
    "graphs",
    "search",
    "errors",
)

_PREAMBLE = """\
# toolbox — functions your program may call

Import from the package (`from toolbox import render_scene, depth_to_points`) or its modules
(`from toolbox.geometry import make_pose`). Units: metres, radians, seconds. Poses are 4×4
`T_world_object` numpy arrays; the world has z up with the table top at z = 0. Cameras are
`{"width", "height", "K" (3, 3), "T_world_camera" (4, 4)}` in the OpenCV convention; depth
is metric along the optical axis, 0 where invalid. Every function raises
`toolbox.ToolboxError` on invalid input.
"""


def toolbox_docs(modules: Sequence[str] | None = None) -> str:
    """Markdown documentation of the toolbox's public API.

    Args:
        modules: module names to include (from `MODULES`), in prompt order; None for all.

    Raises:
        ToolboxError: an unknown module name.
    """
    names = list(MODULES) if modules is None else list(modules)
    unknown = [m for m in names if m not in MODULES]
    if unknown:
        raise ToolboxError(f"unknown toolbox module {unknown[0]!r}; known: {', '.join(MODULES)}")
    parts = [_PREAMBLE]
    for name in (m for m in MODULES if m in names):
        module = importlib.import_module(f"toolbox.{name}")
        parts.append(f"## toolbox.{name}\n\n{inspect.getdoc(module)}\n")
        for public in module.__all__:
            parts.append(_entry(public, getattr(module, public)))
    return "\n".join(parts).rstrip() + "\n"


def _entry(name: str, obj: object) -> str:
    if not callable(obj):  # a constant: its value says it (the module text says what it is)
        return f"### `{name} = {obj!r}`\n"
    doc = inspect.getdoc(obj) or ""
    if inspect.isclass(obj):
        methods = [
            f"#### `{name}.{m}{_signature(getattr(obj, m))}`\n\n{inspect.getdoc(getattr(obj, m))}\n"
            for m, v in sorted(vars(obj).items())
            if not m.startswith("_")
            and (inspect.isfunction(v) or isinstance(v, staticmethod | classmethod))
            and inspect.getdoc(getattr(obj, m))
        ]
        return "\n".join([f"### class `{name}`\n\n{doc}\n", *methods])
    return f"### `{name}{_signature(obj)}`\n\n{doc}\n"


def _signature(fn) -> str:
    sig = inspect.signature(fn)
    params = []
    star_done = False
    for p in sig.parameters.values():
        if p.kind is p.KEYWORD_ONLY and not star_done:
            params.append("*")
            star_done = True
        if p.kind is p.VAR_POSITIONAL:
            star_done = True
            params.append(f"*{p.name}")
        elif p.kind is p.VAR_KEYWORD:
            params.append(f"**{p.name}")
        elif p.default is p.empty:
            params.append(p.name)
        else:
            params.append(f"{p.name}={_default(p.default)}")
    ret = sig.return_annotation
    arrow = (
        ""
        if ret is sig.empty
        else f" -> {ret if isinstance(ret, str) else getattr(ret, '__name__', ret)}"
    )
    return f"({', '.join(params)}){arrow}"


def _default(value: object) -> str:
    if callable(value):
        return getattr(value, "__name__", "<callable>")
    return repr(value)
