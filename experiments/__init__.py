"""The experiment runner: many trials of a policy (`experiments.evaluation`), reliability
studies over authoring runs (`experiments.reliability`), and their fan-out to Ray
(`experiments.scaleout`).

It sits above the physics (`sim`: scenes, observations, the executor, one trial) and above
the runtime whose policies it evaluates (`artifacts.policy`), which it imports directly.
"""
