"""What the prompts say about a domain: task text, what the checks and the robot use, the rules
of every check, cameras, meshes, reference images."""

from __future__ import annotations

import io
import json
from collections.abc import Sequence

import numpy as np

from agent.clients.base import ImageBlock
from agent.prompt import DomainContext, template


def png_bytes(image: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def depth_visual(depth: np.ndarray) -> np.ndarray:
    """Depth [m] as an 8-bit grey image, near = bright, invalid (0) = black."""
    valid = depth > 0
    out = np.zeros(depth.shape, np.uint8)
    if valid.any():
        lo, hi = np.percentile(depth[valid], [1, 99])
        scaled = 1.0 - np.clip((depth - lo) / max(hi - lo, 1e-6), 0.0, 1.0)
        out[valid] = (40 + 215 * scaled[valid]).astype(np.uint8)
    return np.repeat(out[:, :, None], 3, axis=2)


def downscale(image: np.ndarray, max_side: int = 960) -> np.ndarray:
    """Fewer pixels for the model (tokens scale with area); nearest keeps depth edges honest."""
    h, w = image.shape[:2]
    step = max(1, int(np.ceil(max(h, w) / max_side)))
    return image[::step, ::step]


def camera_summary(domain) -> str:
    lines = []
    for name, spec in domain.cameras.items():
        cam = domain.camera(name)
        K = np.asarray(cam["K"])
        role = "default" if name == "front" else "alternative viewpoint"
        lines.append(
            f"- `{name}` ({role}): {cam['width']}×{cam['height']} px, fx = fy = {K[0, 0]:.1f} px, "
            f"at {list(spec.position)} m looking at {list(spec.target)} m"
        )
    lines.append(
        "The checks and the trials draw their cameras around these (the `perceive` task says "
        "how); the camera actually used is always passed as `camera`: do not hard-code one."
    )
    return "\n".join(lines)


def mesh_summary(domain) -> str:
    lines = []
    for key, spec in domain.mesh_specs.items():
        mesh = domain.mesh(key)
        ext = np.round(mesh.extents * 1000).astype(int).tolist()
        n_sym = len(domain.symmetries(key))
        users = [o.id for o in domain.objects if o.mesh == key]
        lines.append(
            f"- `{key}` (objects: {', '.join(users)}): bounding box {ext} mm, "
            f"{n_sym} proper symmetries; frame: {spec.frame}"
        )
    colours = ", ".join(
        f"{o.id} rgb{tuple(int(255 * c) for c in o.colour[:3])}" for o in domain.objects
    )
    lines.append(f"Object colours: {colours}.")
    return "\n".join(lines)


def reference_observations(domain) -> list[tuple[str, dict]]:
    """Observations of the authoring reference (benchmark goal 1, start 1) from the front camera."""
    from sim.observation import observe

    path = domain.benchmark_path(1, 1)
    from domains.instance import Instance

    instance = Instance.from_dict(json.loads(path.read_text()))
    return [
        ("reference start", observe(domain, instance.start, "front")),
        ("reference goal", observe(domain, instance.goal, "front")),
    ]


def domain_facts(domain) -> str:
    """The generated domain section (`agent/prompts/facts.md`): tolerances, the reference
    relations, what perceive reports, the workspace and placement region, the robot, the time
    budgets — every number read from where it is defined (`checks.rules`)."""
    from checks.rules import render

    text, _ = render(template("facts.md"), domain=domain)
    paragraphs = [p.strip() for p in text.split("\n\n") if p.strip()]
    return "\n\n".join(p if p.startswith("#") else " ".join(p.split()) for p in paragraphs)


def function_rules(domain) -> dict[str, str]:
    """Per function, the rule of every check its drafts get (the domain's properties
    included), as a Markdown list."""
    from checks.rulebook import rules_for
    from contracts.functions import FUNCTIONS

    return {
        f: "\n".join(f"- `{s.check}`: {s.text}" for s in rules_for(domain, f)) for f in FUNCTIONS
    }


def build_context(
    domain, observations: Sequence[tuple[str, dict]] = (), toolbox_docs: str = ""
) -> DomainContext:
    """A domain's prompt context; `observations` are (caption, observation) of the reference."""
    images: list[ImageBlock] = []
    for caption, obs in observations:
        images.append(
            ImageBlock(png=png_bytes(downscale(obs["rgb"])), caption=f"{caption}: colour")
        )
        images.append(
            ImageBlock(
                png=png_bytes(downscale(depth_visual(obs["depth"]))), caption=f"{caption}: depth"
            )
        )
    return DomainContext(
        domain=domain.name,
        task=domain.task,
        cameras=camera_summary(domain),
        meshes=mesh_summary(domain),
        images=tuple(images),
        toolbox_docs=toolbox_docs,
        facts=domain_facts(domain),
        rules=function_rules(domain),
    )
