"""Shared helpers of the study tests: small study files written into a temporary folder."""

from __future__ import annotations

from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "scenarios"


def write_study(tmp_path: Path, data: dict, name: str = "study.yaml") -> Path:
    """Write a study mapping as YAML into ``tmp_path`` and return its path."""
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return p


def tiny_simulation_study(tmp_path: Path, masses=(2.0, 6.0), samples: int = 2,
                          duration: float = 0.01, name: str = "tiny_sim") -> Path:
    """A simulate study of the demo pair: mass grid x seeded uniform kp, a few steps each."""
    return write_study(tmp_path, {
        "name": name,
        "base": str(SCENARIOS / "two_ur5_box.yaml"),
        "set": {"simulation.duration": duration},
        "parameters": [{"path": "object.mass", "grid": list(masses)},
                       {"path": "controller.kp", "uniform": {"low": 50.0, "high": 150.0}}],
        "samples": samples,
        "seed": 3,
    }, f"{name}.yaml")


def tiny_grasp_study(tmp_path: Path, sigmas=(0.001, 0.02), samples: int = 5,
                     name: str = "tiny_grasp") -> Path:
    """A grasp study of the two-gripper grasp's contacts under placement errors."""
    return write_study(tmp_path, {
        "name": name,
        "base": str(SCENARIOS / "two_gripper_form_closure.yaml"),
        "mode": "grasp",
        "parameters": [{"perturb_contacts": {"sigma": list(sigmas)}}],
        "samples": samples,
        "seed": 7,
    }, f"{name}.yaml")


def rows_by_case(table) -> dict[str, dict]:
    """``{case_id: row}`` of a pyarrow table."""
    return {r["case_id"]: r for r in table.to_pylist()}
