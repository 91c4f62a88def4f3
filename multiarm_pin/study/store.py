"""The results folder of a study: rows written as cases finish, never lost.

Layout of ``DIR``::

    study.json                 the study: name, files, every case (id, key, params, overrides)
    cases/case_00042/summary.json   the case's summary (run summary or grasp report)
    cases/case_00042/row.json       its row of the table (written last: the case is finished)
    results.parquet            the table (one row per finished case), rebuilt from the rows
    report.md, plots/*.png     the report (:mod:`multiarm_pin.study.report`)

Every file is written atomically (a temporary file in the same folder, then renamed), so a
study killed at any moment leaves whole files only; the rows in ``cases/`` are the truth and
``results.parquet`` is rebuilt from them. A case is finished when its ``row.json`` exists
with the case's current key and a status other than ``lost`` (a case whose workers kept
dying); a resume runs every other case.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from multiarm_pin.app import results_io
from multiarm_pin.exceptions import StudyError

TABLE_NAME = "results.parquet"
"""File name of the table in a results folder."""


def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) atomically, creating the folder.

    Through :func:`multiarm_pin.app.results_io.write_atomic`: a temporary file renamed into
    place, so a reader never sees half a file.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    results_io.write_atomic(path, text.encode("utf-8"))


def _json_default(x):
    try:
        import numpy as np

        if isinstance(x, np.ndarray):
            return x.tolist()
        if isinstance(x, np.generic):
            return x.item()
    except ImportError:  # pragma: no cover
        pass
    return str(x)


def _clean(x):
    """JSON with NaN/inf as null (strict JSON readers reject NaN)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_clean(v) for v in x]
    return x


def dumps(x) -> str:
    """JSON text of ``x`` (numpy values converted, NaN as null, indented)."""
    return json.dumps(_clean(json.loads(json.dumps(x, default=_json_default))), indent=1)


class ResultsFolder:
    """A study's results folder (see the module docstring).

    Args:
        path: the folder.
    """

    def __init__(self, path):
        self.path = Path(path)
        self.cases_dir = self.path / "cases"

    @property
    def table_path(self) -> Path:
        """``DIR/results.parquet``."""
        return self.path / TABLE_NAME

    def prepare(self, spec, cases, resume: bool) -> dict[str, dict]:
        """Create the folder (or check it holds this study) and read its finished rows.

        Args:
            spec: the :class:`~multiarm_pin.study.spec.StudySpec`.
            cases: its cases.
            resume: ``--resume`` was asked: the folder must already hold this study.

        Returns:
            ``{case_id: row}`` of the finished cases that are still cases of the study.

        Raises:
            StudyError: ``--resume`` without a study in the folder, or the folder holds
                another study (another name), or is a file.
        """
        self.check(spec, resume)
        self.path.mkdir(parents=True, exist_ok=True)
        write_atomic(self.path / "study.json", dumps({
            "name": spec.name, "study_file": str(Path(spec.file).resolve()),
            "base_file": spec.base_file, "base_sha256": spec.base_text_hash,
            "mode": spec.mode, "metrics": list(spec.metrics), "parameters": spec.varied,
            "n_cases": len(cases),
            "cases": [{"case_id": c.case_id, "key": c.key, "params": c.params,
                       "overrides": c.overrides} for c in cases],
        }))
        return self.finished(cases)

    def check(self, spec, resume: bool) -> None:
        """Check, writing nothing, that the folder may receive this study.

        Raises:
            StudyError: see :meth:`prepare`.
        """
        study_file = self.path / "study.json"
        if self.path.exists() and not self.path.is_dir():
            raise StudyError(str(self.path), "--out", "exists and is not a folder")
        if study_file.is_file():
            try:
                old = json.loads(study_file.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise StudyError(str(study_file), "", f"unreadable study.json: {exc}") from exc
            if old.get("name") != spec.name:
                raise StudyError(str(self.path), "--out", f"holds the results of study "
                                 f"{old.get('name')!r}, not {spec.name!r}: choose another "
                                 "folder")
        elif resume:
            raise StudyError(str(self.path), "--resume", "no study to resume in this folder "
                             "(no study.json); run without --resume to start it")
        elif self.path.is_dir() and any(self.path.iterdir()):
            raise StudyError(str(self.path), "--out", "exists and is not empty, and holds no "
                             "study: choose another folder")

    def finished(self, cases) -> dict[str, dict]:
        """``{case_id: row}`` of the cases whose row is written with their current key."""
        done = {}
        for c in cases:
            row = self.read_row(c.case_id)
            if row is not None and row.get("key") == c.key and row.get("status") != "lost":
                done[c.case_id] = row
        return done

    def read_row(self, case_id: str) -> dict | None:
        """The row of a case, or None when it is not written (or unreadable)."""
        p = self.cases_dir / case_id / "row.json"
        try:
            row = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return {k: (float("nan") if v is None and k not in ("error",) else v)
                for k, v in row.items()}

    def write_case(self, row: dict, summary: dict | None) -> None:
        """Write a finished case: its summary, then its row (the row marks it finished)."""
        d = self.cases_dir / row["case_id"]
        if summary is not None:
            write_atomic(d / "summary.json", dumps(summary))
        write_atomic(d / "row.json", dumps(row))

    def write_table(self, rows) -> Path:
        """Write ``results.parquet`` (atomically) from rows sorted by case index."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        buf = pa.BufferOutputStream()
        pq.write_table(rows_to_table(rows), buf)
        self.path.mkdir(parents=True, exist_ok=True)
        results_io.write_atomic(self.table_path, buf.getvalue().to_pybytes())
        return self.table_path


def rows_to_table(rows):
    """A ``pyarrow.Table`` of rows (dicts), sorted by ``index``; missing values are null."""
    import pyarrow as pa

    rows = sorted(rows, key=lambda r: r.get("index", 0))
    names: list[str] = []
    for r in rows:
        for k in r:
            if k not in names:
                names.append(k)
    cols = {}
    for k in names:
        vals = [r.get(k) for r in rows]
        if all(v is None or isinstance(v, float | int) and not isinstance(v, bool)
               for v in vals) and k not in ("case_id", "key", "status", "error", "worker",
                                            "run_token"):
            kind = pa.int64() if k in ("index", "sample") else pa.float64()
            cols[k] = pa.array([None if v is None else (int(v) if kind == pa.int64()
                                                        else float(v)) for v in vals], kind)
        else:
            cols[k] = pa.array([None if v is None else str(v) for v in vals], pa.string())
    return pa.table(cols) if cols else pa.table({})


def read_table(path):
    """Read a study's ``results.parquet`` (a file or a results folder) as a ``pyarrow.Table``.

    Raises:
        StudyError: missing or unreadable file.
    """
    p = Path(path)
    if p.is_dir():
        p = p / TABLE_NAME
    try:
        import pyarrow.parquet as pq

        return pq.read_table(p)
    except (OSError, ValueError) as exc:
        raise StudyError(str(p), "", f"cannot read the results table: {exc}") from exc


__all__ = ["TABLE_NAME", "ResultsFolder", "dumps", "read_table", "rows_to_table",
           "write_atomic"]
