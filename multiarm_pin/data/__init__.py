"""Files shipped with the package: example scenarios (with grasp and study files) and robots.

- ``scenarios/*.yaml``: scenario files (:mod:`multiarm_pin.app.scenario`); ``two_ur5_box.yaml``
  is the demo's. ``scenarios/grasps/*.yaml``: grasp files (``multiarm-pin grasp``).
  ``scenarios/studies/*.yaml``: study files (``multiarm-pin sweep``).
- ``robots/``: URDF robots of our own (``mp6/mp6.urdf``, ``mp6/mp6_4f.urdf``), which
  scenarios name by a path relative to their own folder (``../robots/mp6/mp6.urdf``).

They are read in place with :mod:`importlib.resources` (an installed wheel keeps them as
plain files in ``site-packages``); a source checkout reaches the same folders through the
top-level ``scenarios`` and ``robots`` links.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from multiarm_pin.exceptions import InputError

DEMO_SCENARIO = "two_ur5_box.yaml"
"""File name (in ``scenarios/``) of the scenario ``multiarm-pin demo`` runs."""


def data_path(*parts: str) -> Path:
    """Path of a shipped file or folder, e.g. ``data_path("scenarios", "two_ur5_box.yaml")``.

    Raises:
        InputError: the package is not installed as plain files (e.g. zipped), so the data
            cannot be read in place.
    """
    root = files(__name__)
    if not isinstance(root, Path):
        raise InputError(f"multiarm_pin's data is not a folder on disk ({root}); install the "
                         "package from a wheel or a source checkout")
    return root.joinpath(*parts)


def shipped_files(folder: str, suffix: str = ".yaml") -> list[Path]:
    """The shipped files of ``folder`` (``"scenarios"``, ``"scenarios/grasps"``, ...), sorted."""
    return sorted(p for p in data_path(*folder.split("/")).iterdir()
                  if p.is_file() and p.name.endswith(suffix))


__all__ = ["DEMO_SCENARIO", "data_path", "shipped_files"]
