"""Every name a package lists in `__all__` resolves (STYLE: the package re-exports what users import)."""

from __future__ import annotations

import importlib

import pytest

PACKAGES = ["contracts", "sandbox", "toolbox", "domains", "sim", "agent", "artifacts"]


@pytest.mark.parametrize("name", PACKAGES)
def test_all_names_resolve(name):
    module = importlib.import_module(name)
    for attr in getattr(module, "__all__", []):
        assert hasattr(module, attr), f"{name}.__all__ lists '{attr}', which does not resolve"


def test_contracts_exports_the_representation():
    import contracts

    assert {"validate", "to_jsonable", "ContractError", "SCHEMA_NAMES", "se3"} <= set(
        contracts.__all__
    )
    # the representation is plain JSON-style values: no typed layer beside the schemas
    assert not {"SceneSpec", "RelationGraph", "Instance", "plan_from_dict"} & set(dir(contracts))
