"""The oracle geometry: what generators, settling, the plan checks, trial scoring and the
executor's grasp model agree on — convex parts, interpenetration, support and stability.

Pure numpy/scipy (no simulator, no I/O), so it runs on the host and inside the sandbox (the
toolbox re-exports its documented names to programs).
"""
