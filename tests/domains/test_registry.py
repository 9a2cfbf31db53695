"""The domain registry: names, loading, and the unknown-name message."""

from __future__ import annotations

import pytest

import domains
from contracts.errors import UsageError


def test_names_are_the_three_domains():
    assert domains.names() == ("assembly", "cubes", "tangram")


def test_load_returns_one_shared_instance():
    assert domains.load("cubes") is domains.load("cubes")
    assert domains.load("cubes").name == "cubes"


def test_unknown_domain_lists_the_known_ones():
    with pytest.raises(domains.UnknownDomainError) as e:
        domains.load("cube")
    assert str(e.value) == "unknown domain 'cube'; known: assembly, cubes, tangram"
    assert isinstance(e.value, UsageError)


def test_registering_a_name_twice_fails():
    with pytest.raises(ValueError, match="twice"):
        domains.register("cubes")(type("Dup", (domains.Domain,), {}))


def test_unknown_object_lists_the_catalogue():
    with pytest.raises(domains.UnknownObjectError, match="known: red, green"):
        domains.load("cubes").object("pink")
