"""Helpers shared by the benchmark programs: CSV tables of dataclass rows, integer lists.

Imported by ``solver_vs_kkt.py`` and ``closed_loop.py`` (run as scripts from this folder, or
with it on ``sys.path``).
"""

from __future__ import annotations

import argparse
import csv
import math
from collections.abc import Callable, Sequence
from dataclasses import fields
from pathlib import Path


def scientific(x):
    """A float as ``1.234560e-05`` (``nan`` for NaN); anything else unchanged."""
    if isinstance(x, float):
        return "nan" if math.isnan(x) else f"{x:.6e}"
    return x


def general(x):
    """A float as ``1.23456e-05`` (six significant digits); anything else unchanged."""
    return f"{x:.6g}" if isinstance(x, float) else x


def write_rows_csv(rows: Sequence, path: Path, row_type: type,
                   cell: Callable[[object], object] = scientific) -> None:
    """Write dataclass ``rows`` of ``row_type`` as a CSV table: one column a field, in order.

    Args:
        rows: the rows (instances of the dataclass ``row_type``).
        path: the CSV file (overwritten).
        row_type: the dataclass; its fields name the columns (written even with no rows).
        cell: how a value is written (:func:`scientific` or :func:`general`).
    """
    columns = [f.name for f in fields(row_type)]
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow([cell(getattr(r, c)) for c in columns])


def int_list(text: str) -> tuple[int, ...]:
    """``argparse`` type: comma-separated positive integers, e.g. ``"2,4,8"``."""
    try:
        values = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise argparse.ArgumentTypeError(f"expected positive integers, got {text!r}")
    return values
