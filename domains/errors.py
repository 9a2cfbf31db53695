"""Errors of the domain layer: registry look-ups, catalogue files and instance generation."""

from __future__ import annotations

from collections.abc import Iterable

from contracts.errors import RivetError, UsageError


class DomainError(RivetError):
    """A domain's own files or generator are broken (a bug in the project, exit code 1)."""


class UnknownDomainError(UsageError):
    """The user named a domain that is not registered."""

    def __init__(self, name: str, known: Iterable[str]) -> None:
        self.name = name
        self.known = tuple(known)
        super().__init__(f"unknown domain {name!r}; known: {', '.join(self.known)}")


class UnknownObjectError(UsageError):
    """A scene names an object (or mesh) the domain's catalogue does not have."""

    def __init__(self, domain: str, what: str, name: str, known: Iterable[str]) -> None:
        self.domain = domain
        self.what = what
        self.name = name
        self.known = tuple(known)
        super().__init__(f"{domain}: unknown {what} {name!r}; known: {', '.join(self.known)}")


class GenerationError(DomainError):
    """The instance generator could not produce a valid instance for a seed."""
