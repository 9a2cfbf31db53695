"""The authoring agent: dependency-ordered generation, repair loop, model clients, freezing.

Import what you need from the submodules (`agent.loop`, `agent.clients`, …): this package's
`__init__` stays light so that `artifacts` (which reads `agent.dag`) never pulls in the model
SDK.
"""

from agent.dag import FUNCTIONS, authoring_order

__all__ = ["FUNCTIONS", "authoring_order"]
