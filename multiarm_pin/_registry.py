"""The one look-up of every registry (joint types, robots, solvers, controllers, integrators).

Each registry is a ``dict[str, Entry]`` of frozen dataclasses keyed by the entry's name (the
name a scenario file uses too). :func:`lookup` is its single dispatch point: an unknown name
raises an error that lists the known names and, when one is close, suggests it.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Mapping
from typing import TypeVar

from multiarm_pin.exceptions import InputError, MultiArmError

T = TypeVar("T")


def unknown_name_message(what: str, name: object, known: Iterable[str],
                         plural: str | None = None) -> str:
    """``"unknown <what> 'x'; known <plural>: a, b, c; did you mean 'a'?"``.

    Args:
        what: the kind of name (``"solver"``, ``"joint type"``...).
        name: the name that was asked for.
        known: the names that would have worked (listed sorted).
        plural: how the list is introduced (default ``what + "s"``).
    """
    names = sorted(known)
    close = difflib.get_close_matches(name, names, n=1) if isinstance(name, str) else []
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return f"unknown {what} {name!r}; known {plural or what + 's'}: {', '.join(names)}{hint}"


def lookup(registry: Mapping[str, T], name: str, what: str,
           error: type[MultiArmError] = InputError, plural: str | None = None) -> T:
    """The entry of ``name`` in ``registry``.

    Args:
        registry: the registry (name -> entry).
        name: the name asked for.
        what: the kind of name, for the message.
        error: the exception type raised for an unknown name (an :class:`InputError`
            subclass or another :class:`MultiArmError` taking one message).
        plural: how the message introduces the known names (default ``what + "s"``).

    Raises:
        error: ``name`` is not in the registry (the message lists the known names, with a
            did-you-mean when one is close).
    """
    try:
        return registry[name]
    except (KeyError, TypeError):
        raise error(unknown_name_message(what, name, registry, plural)) from None


__all__ = ["lookup", "unknown_name_message"]
