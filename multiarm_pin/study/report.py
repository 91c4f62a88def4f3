"""The report of a study: ``report.md`` and plots of each metric against each parameter.

One concept at several layers: each layer's ``report.py`` (``grasp``, ``study``, ``feasibility``,
``design``) makes that layer's report of its results.


The plots are ``plots/<metric>__vs__<parameter>.png``.

For a verdict metric (``form_closure``, ``within_limits``) the plot shows the fraction of
cases where it holds at each value of the parameter, counting a failed case (an error row,
e.g. a contact point pushed off its face) as not holding; for the other metrics, every
case that ran (points) and the mean at each grid value (line).

Twins: ``multiarm_pin.feasibility.report``, ``multiarm_pin.design.report`` and
``multiarm_pin.grasp.report`` (the same role, a package's report of its own results, in four
packages: this one writes a study's ``report.md`` and its plots; ``feasibility.report`` returns
the feasibility of a simulated run (limits, collisions) as a ``FeasibilityReport``;
``design.report`` writes a design's results folder (scenarios, pictures, ``report.md``, the best
run); ``grasp.report`` reads grasp files, analyses them, formats the report and draws its
picture).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from multiarm_pin.study.metrics import BOOLEAN_METRICS

MAX_FULL_TABLE = 60
"""Studies with at most this many cases get their whole table in ``report.md``."""


def _columns(table) -> dict[str, list]:
    return {name: table.column(name).to_pylist() for name in table.column_names}


def _numeric(values) -> np.ndarray | None:
    try:
        return np.array([np.nan if v is None else float(v) for v in values], dtype=float)
    except (TypeError, ValueError):
        return None


def _fmt(v) -> str:
    """A table cell: numbers to 4 digits, text whole (on one line, ``|`` escaped)."""
    if v is None:
        return ""
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return f"{v:.4g}"
    return _one_line(str(v)).replace("|", "\\|")


def _one_line(text: str) -> str:
    """``text`` with its line breaks and runs of spaces made single spaces (nothing cut)."""
    return " ".join(text.split())


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_")


def summary_by_value(table, spec, parameter: str) -> list[dict]:
    """Per value of a grid parameter: cases, failures, and each metric's mean/min/max.

    Verdict metrics give the fraction of all cases (failures counted as false).
    """
    cols = _columns(table)
    values = cols[parameter]
    ok = np.array([s == "ok" for s in cols["status"]])
    out = []
    for v in sorted(set(values), key=lambda x: (x is None, x)):
        sel = np.array([x == v for x in values])
        entry = {"value": v, "cases": int(sel.sum()), "failed": int((sel & ~ok).sum())}
        for m in spec.metrics:
            a = _numeric(cols[m])
            if m in BOOLEAN_METRICS:
                entry[f"{m} fraction"] = float(np.nansum(np.where(sel, a, 0.0)) / sel.sum())
                continue
            good = a[sel & ok & np.isfinite(a)]
            entry[f"{m} mean"] = float(good.mean()) if good.size else float("nan")
            entry[f"{m} min"] = float(good.min()) if good.size else float("nan")
            entry[f"{m} max"] = float(good.max()) if good.size else float("nan")
        out.append(entry)
    return out


def _md_table(rows: list[dict]) -> list[str]:
    if not rows:
        return []
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(_fmt(r.get(k)) for k in keys) + " |" for r in rows]
    return lines


def largest_passing(table, spec, parameter: str, metric: str):
    """Largest value of ``parameter`` up to which every case has ``metric`` true.

    Returns:
        ``(value or None, first failing value or None)``: ``None`` when the first value
        already fails / when none fails.
    """
    rows = summary_by_value(table, spec, parameter)
    best = None
    for r in rows:
        if r[f"{metric} fraction"] < 1.0:
            return best, r["value"]
        best = r["value"]
    return best, None


def write_report(out_dir, spec, table) -> Path:
    """Write ``report.md`` and the plots into ``out_dir``; return the report's path."""
    out = Path(out_dir)
    plots_dir = out / "plots"
    plots_dir.mkdir(parents=True, exist_ok=True)
    cols = _columns(table)
    n = table.num_rows
    status = cols.get("status", [])
    n_ok = sum(1 for s in status if s == "ok")
    lines = [f"# Study {spec.name}", ""]
    if spec.description:
        lines += [spec.description, ""]
    lines += [f"- base file: `{Path(spec.base_file).name}` (mode `{spec.mode}`)",
              f"- cases: {n} ({n_ok} ran, {n - n_ok} failed)",
              f"- varied: {', '.join(f'`{p}`' for p in spec.varied)}; samples per grid point: "
              f"{spec.samples}; seed: {spec.seed}",
              f"- fixed: {', '.join(f'`{k}` = {v}' for k, v in spec.fixed.items()) or 'none'}",
              "- table: `results.parquet` (one row per case); each case's summary in "
              "`cases/<case_id>/summary.json`", ""]
    grid_params = [p.path for p in spec.parameters if p.is_grid]
    for p in grid_params:
        if p not in cols:
            continue
        rows = summary_by_value(table, spec, p)
        if rows and max(r["cases"] for r in rows) == 1:  # one case a value: its metrics
            rows = [{k.removesuffix(" mean").removesuffix(" fraction"): v
                     for k, v in r.items() if not k.endswith((" min", " max"))} for r in rows]
        lines += [f"## Against `{p}`", ""] + _md_table(rows) + [""]
        for m in spec.metrics:
            if m in BOOLEAN_METRICS and len(grid_params) == 1:
                best, first_fail = largest_passing(table, spec, p, m)
                lines.append(f"- `{m}` holds in every case up to `{p}` = {_fmt(best)}"
                             + (f"; first value where it fails: {_fmt(first_fail)}"
                                if first_fail is not None else " (the whole range)"))
        lines.append("")
    base = str(spec.base_file)  # the base file by its name: no machine paths in reports
    errors = [(c, _one_line(str(e).replace(base, Path(base).name)))
              for c, s, e in zip(cols.get("case_id", []), status, cols.get("error", []),
                                 strict=False) if s != "ok"]
    if errors:  # every message whole: the kinds (numbers as #), then each kind's first case
        kinds: dict[str, list[str]] = {}
        for c, e in errors:
            kinds.setdefault(re.sub(r"[-+]?\d[\d.e+-]*", "#", e), []).append(c)
        lines += ["## Failed cases", ""]
        lines += [f"- {len(cs)} x {k} (first: {cs[0]})"
                  for k, cs in sorted(kinds.items(), key=lambda x: -len(x[1]))]
        lines += ["", "First failures:", ""] + [f"- {c}: {e}" for c, e in errors[:5]] + [""]
    plots = _plots(plots_dir, spec, cols)
    if plots:
        lines += ["## Plots", ""] + [f"![{p.stem}](plots/{p.name})" for p in plots] + [""]
    if n <= MAX_FULL_TABLE:
        keys = ["case_id", *spec.varied, "sample", *spec.metrics, "status", "error"]
        keys = [k for k in keys if k in cols]
        shown = [{k: cols[k][i] for k in keys} for i in range(n)]
        for row in shown:  # the base file by its name here too
            if row.get("error"):
                row["error"] = str(row["error"]).replace(base, Path(base).name)
        lines += ["## All cases", ""]
        lines += _md_table(shown) + [""]
    path = out / "report.md"
    from multiarm_pin.study.store import write_atomic

    write_atomic(path, "\n".join(lines))
    return path


def _plots(plots_dir: Path, spec, cols) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = np.array([s == "ok" for s in cols.get("status", [])])
    paths = []
    for p in spec.parameters:
        x = _numeric(cols.get(p.path, []))
        if x is None or x.size == 0:
            continue  # a vector-valued parameter: no axis to plot against
        for m in spec.metrics:
            y = _numeric(cols[m])
            fig, ax = plt.subplots(figsize=(6, 4))
            if m in BOOLEAN_METRICS or p.is_grid:
                xs = np.unique(x[np.isfinite(x)])
            if m in BOOLEAN_METRICS:
                frac = [np.nansum(np.where(x == v, y, 0.0)) / max(np.sum(x == v), 1)
                        for v in xs]
                ax.plot(xs, frac, "o-")
                ax.set_ylim(-0.05, 1.05)
                ax.set_ylabel(f"fraction of cases with {m}")
            else:
                sel = ok & np.isfinite(y)
                ax.plot(x[sel], y[sel], ".", alpha=0.4, label="cases")
                if p.is_grid:
                    means = [np.mean(y[sel & (x == v)]) if np.any(sel & (x == v)) else np.nan
                             for v in xs]
                    ax.plot(xs, means, "o-", label="mean")
                    ax.legend()
                ax.set_ylabel(m)
            ax.set_xlabel(p.path + (" [m]" if p.kind == "perturb_contacts" else ""))
            ax.set_title(f"{spec.name}: {m} vs {p.path}")
            ax.grid(True, alpha=0.3)
            fig.tight_layout()
            path = plots_dir / f"{_safe(m)}__vs__{_safe(p.path)}.png"
            fig.savefig(path, dpi=80)
            plt.close(fig)
            paths.append(path)
    return paths


__all__ = ["largest_passing", "summary_by_value", "write_report"]
