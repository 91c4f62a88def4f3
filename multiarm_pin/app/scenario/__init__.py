"""Scenario files: format and validation (:mod:`.schema`), specs (:mod:`.specs`), building.

``load_scenario(path)`` reads and validates a file into a :class:`Scenario`;
``build_scenario(scenario)`` loads the arms, places them and builds the
:class:`~multiarm_pin.system.MultiArmSystem` with its checked initial state
(:class:`BuiltScenario`). The file format is described in :mod:`.schema`.
"""

from multiarm_pin.app.scenario.build import BuiltScenario, build_arm, build_object, build_scenario
from multiarm_pin.app.scenario.schema import load_scenario, parse_scenario
from multiarm_pin.app.scenario.specs import *  # noqa: F403 (the specs and names, re-exported)
from multiarm_pin.app.scenario.specs import __all__ as _specs_all
from multiarm_pin.yaml_reader import did_you_mean

__all__ = [
    *_specs_all,
    "BuiltScenario",
    "build_arm",
    "build_object",
    "build_scenario",
    "did_you_mean",
    "load_scenario",
    "parse_scenario",
]
