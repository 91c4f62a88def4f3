"""Design: find where the arms and the contacts go (``multiarm-pin design SPEC.yaml``).

From a design spec (the object, the task, the arms available, where their bases may go) the
search returns ranked designs, each a complete scenario that ``multiarm-pin run`` accepts:

- :mod:`.spec`: reading and validating spec files (:func:`load_design`), named grippers;
- :mod:`.candidates`: candidate designs (bases, contacts, IK branches), sampled and refined;
- :mod:`.assessment`: the checks every returned design passes, and its scores;
- :mod:`.scoring`: the scores, the weighted objective, the Pareto front;
- :mod:`.search`: the search, in parallel on Dask (:func:`run_design`);
- :mod:`.report`: the results folder (scenarios, pictures, ``report.md``, the best run);
- :mod:`.cli`: the ``design`` subcommand.

The package itself is callable: ``multiarm_pin.design(spec)`` is :func:`design`.
"""

from __future__ import annotations

import sys

from multiarm_pin.design.scoring import SCORES
from multiarm_pin.design.search import Design, DesignResult, run_design
from multiarm_pin.design.spec import DesignSpec, load_design, parse_design


def design(spec, *, workers: int = 1, scheduler: str | None = None,
           seed: int | None = None) -> DesignResult:
    """Find ranked designs for a design spec: where the arms' bases and contacts go.

    Args:
        spec: a spec file path, a parsed mapping, or a :class:`DesignSpec`.
        workers: processes of a local Dask cluster assessing candidates (1: this process).
        scheduler: address of an existing Dask scheduler instead.
        seed: overrides the spec's ``search.seed``.

    Returns:
        :class:`DesignResult`: ``designs`` (best first; each ``scenario`` a mapping that
        ``multiarm-pin run`` accepts as YAML), ``pareto``, and the search's counts.

    Raises:
        DesignError: an invalid spec.
        DesignImpossibleError: no candidate met every condition (the message names the
            condition and the best value reached).
    """
    if isinstance(spec, dict):
        spec = parse_design(spec)
    return run_design(spec, workers=workers, scheduler=scheduler, seed=seed)


__all__ = ["SCORES", "Design", "DesignResult", "DesignSpec", "design", "load_design",
           "parse_design", "run_design"]


class _CallableModule(type(sys)):
    """The package, callable: ``multiarm_pin.design(spec)`` is :func:`design`."""

    def __call__(self, spec, **kwargs) -> DesignResult:
        return design(spec, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
