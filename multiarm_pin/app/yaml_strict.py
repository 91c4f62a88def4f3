"""Strict YAML loading, now in :mod:`multiarm_pin.yaml_reader` (shared with the grasp files).

Kept as an import path for :mod:`multiarm_pin.study.spec`.
"""

from multiarm_pin.yaml_reader import StrictLoader, load_yaml_file, load_yaml_text

__all__ = ["StrictLoader", "load_yaml_file", "load_yaml_text"]
