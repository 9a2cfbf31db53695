"""Dimensions of the assembly parts [m] (shared by the mesh script and the generator)."""

from __future__ import annotations

DEPTH = 0.035  # extrusion depth of profiled parts, the jaw width [m]
ARC_SEGMENTS = 16

PILLAR = (0.03, 0.03, 0.08)  # [m]
BEAM = (0.16, DEPTH, 0.02)
BLOCK = (0.05, DEPTH, 0.03)
ARCH_W, ARCH_H, ARCH_R, ARCH_SPRING = (
    0.12,
    0.065,
    0.03,
    0.02,
)  # width, height, opening radius, springline
ROOF_W, ROOF_H = 0.14, 0.04
CYL_R, CYL_H = 0.02, 0.06
L_FOOT = (0.08, 0.03)  # length, height of the foot
L_LEG = (0.03, 0.04)  # width, height of the leg above the foot, at the -x end
