"""The authoring agent: dependency-ordered generation, repair loop, model clients, freezing.

Import what you need from the submodules (`agent.loop`, `agent.clients`, …); the function DAG
is `contracts.functions`.
"""
