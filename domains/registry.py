"""The domain registry: domains add themselves by name and are loaded by name.

Modelled on dm_control's `suite`: each domain package decorates its `Domain` subclass with
`@register("name")`; `load` builds one shared instance per name.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

from domains.errors import UnknownDomainError

if TYPE_CHECKING:
    from domains.base import Domain

_D = TypeVar("_D", bound="type[Domain]")

_FACTORIES: dict[str, Callable[[], Domain]] = {}
_LOADED: dict[str, Domain] = {}


def register(name: str) -> Callable[[_D], _D]:
    """Class decorator: register a `Domain` subclass under `name`."""

    def decorate(cls: _D) -> _D:
        if name in _FACTORIES:
            raise ValueError(f"domain {name!r} is registered twice")
        _FACTORIES[name] = cls
        return cls

    return decorate


def names() -> tuple[str, ...]:
    """The registered domain names, sorted."""
    return tuple(sorted(_FACTORIES))


def load(name: str) -> Domain:
    """The domain called `name` (one shared instance per name).

    Raises:
        UnknownDomainError: no domain has that name; the message lists the known ones.
    """
    if name not in _FACTORIES:
        raise UnknownDomainError(name, names())
    if name not in _LOADED:
        _LOADED[name] = _FACTORIES[name]()
    return _LOADED[name]
