"""The trial store of a campaign: ``DIR/trials.sqlite`` (SPEC 10).

A campaign (``stressbots montecarlo``, ``stressbots study``) commits every trial as it finishes, one
SQLite transaction per trial, so that Ctrl-C, a crash or ``kill -9`` loses no finished trial and
``--resume`` runs only the missing ones. The store is an ordinary SQLite file (stdlib :mod:`sqlite3`):
open it with ``sqlite3``, pandas (``pd.read_sql("select * from trials", con)``) or :func:`read_rows`.

Tables
------
``campaign(key TEXT PRIMARY KEY, value TEXT)``
    JSON values: ``format`` (``stressbots.trials/1``), ``settings`` (the campaign's fingerprint: what
    decides the outcomes, compared on ``--resume``), ``info`` (provenance that does not decide them),
    ``created_utc``.
``cells(cell INTEGER PRIMARY KEY, label TEXT, params TEXT)``
    The conditions of each cell (a noise scale of ``montecarlo --sweep``, a grid point of a study);
    ``params`` is JSON.
``trials``
    One row per finished trial (:data:`TRIAL_COLUMNS`): ``trial`` is the campaign-wide number
    (``cell * trials_per_cell + cell_trial``), ``seed`` the plant's and controller's seed,
    ``success`` 0/1, ``failure`` the reason, ``shape_error_um`` the RMS shape error after the best rigid
    alignment, ``duration_s`` the *simulated* duration, ``wall_s`` the wall time the trial took.

Durability
----------
WAL journal with ``synchronous=NORMAL``: a committed trial survives the death of the process (Ctrl-C,
``kill -9``, a crash); after a power cut the last few commits may be lost, never the file's consistency,
and ``--resume`` re-runs them. Inserts are idempotent (``INSERT OR IGNORE`` on the primary key): a trial
that arrives twice (a Dask task re-run after its worker died, two runs resuming the same store) is kept
once, and since a trial is a pure function of its seed and settings both copies are the same.
"""

from __future__ import annotations

import csv
import io
import json
import math
import sqlite3
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from .errors import StressbotsError

__all__ = [
    "STORE_NAME",
    "FORMAT",
    "TRIAL_COLUMNS",
    "TrialStore",
    "settings_differences",
    "read_rows",
    "read_settings",
    "csv_text",
    "write_parquet",
]

STORE_NAME = "trials.sqlite"
FORMAT = "stressbots.trials/1"

TRIAL_COLUMNS: tuple[tuple[str, str], ...] = (
    ("trial", "INTEGER PRIMARY KEY"),
    ("cell", "INTEGER NOT NULL"),
    ("cell_trial", "INTEGER NOT NULL"),
    ("seed", "INTEGER NOT NULL"),
    ("noise_scale", "REAL"),
    ("success", "INTEGER NOT NULL"),
    ("failure", "TEXT"),
    ("shape_error_um", "REAL"),
    ("placement_error_um", "REAL"),
    ("heading_error_deg", "REAL"),
    ("duration_s", "REAL"),
    ("replans", "INTEGER"),
    ("docked", "INTEGER"),
    ("robots", "INTEGER"),
    ("error", "TEXT"),
    ("wall_s", "REAL"),
    ("worker", "TEXT"),
    ("finished_utc", "TEXT"),
)
"""Columns of the ``trials`` table (SPEC 10 names the first ones; the rest is what a trial reports)."""

_NAMES = tuple(name for name, _ in TRIAL_COLUMNS)
_BUSY_TIMEOUT_MS = 30_000  # a reader (pandas, sqlite3 shell) may hold the file briefly


def _utc_now() -> str:
    return datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _db_value(v: Any) -> Any:
    """SQLite has no NaN (it stores NULL); booleans become 0/1."""
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def settings_differences(stored: Mapping[str, Any], current: Mapping[str, Any]) -> list[str]:
    """What differs between two campaign fingerprints, one phrase per key, in key order.

    >>> settings_differences({"seed": 1, "trials": 10}, {"seed": 2, "trials": 10})
    ['seed 1 in the store, 2 now']
    >>> settings_differences({"a": 1}, {"a": 1, "b": 2})
    ['b missing in the store, 2 now']
    """
    out = []
    for key in list(stored) + [k for k in current if k not in stored]:
        a, b = stored.get(key, _MISSING), current.get(key, _MISSING)
        if a != b:
            out.append(f"{key} {_short(a)} in the store, {_short(b)} now{_KEY_NOTES.get(key, '')}")
    return out


class _Missing:
    def __repr__(self) -> str:
        return "missing"


_MISSING = _Missing()


_KEY_NOTES = {"code_sha256": " (stressbots' own sources changed since the store was made)"}


def _short(v: Any, limit: int = 60) -> str:
    if isinstance(v, str) and len(v) == 64 and all(c in "0123456789abcdef" for c in v):
        return v[:12]  # a hash: its head tells them apart
    if v is _MISSING:
        return "missing"
    text = v if isinstance(v, str) else json.dumps(v, sort_keys=True)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _connect(path: Path | str) -> sqlite3.Connection:
    con = sqlite3.connect(str(path), timeout=_BUSY_TIMEOUT_MS / 1000.0, isolation_level=None)
    con.execute(f"PRAGMA busy_timeout = {_BUSY_TIMEOUT_MS}")
    return con


def _open_readonly(path: Path | str) -> sqlite3.Connection:
    p = Path(path)
    if not p.is_file():
        raise StressbotsError("no such trial store", source=str(p))
    try:
        con = _connect(p)
        con.execute("SELECT value FROM campaign WHERE key = 'format'").fetchone()
    except sqlite3.DatabaseError as exc:
        raise StressbotsError(f"is not a stressbots trial store ({exc})", source=str(p)) from None
    return con


def _is_empty(p: Path) -> bool:
    """True for an empty file or an SQLite database without a single table (no campaign was stored)."""
    if p.stat().st_size == 0:
        return True
    try:
        con = _connect(p)
        try:
            return con.execute("SELECT count(*) FROM sqlite_master").fetchone()[0] == 0
        finally:
            con.close()
    except sqlite3.DatabaseError:
        return False


class TrialStore:
    """An open trial store (one writer: the process that runs the campaign).

    Use :meth:`open`; close with :meth:`close` or a ``with`` block.
    """

    def __init__(self, path: Path, con: sqlite3.Connection, settings: Mapping[str, Any]):
        self.path = path
        self._con = con
        self.settings = settings

    # -- opening ---------------------------------------------------------------------------------------

    @classmethod
    def open(cls, path: Path | str, settings: Mapping[str, Any], *, resume: bool = False, overwrite: bool = False,
             info: Mapping[str, Any] | None = None, cells: Iterable[tuple[str, Mapping[str, Any]]] = ()) -> TrialStore:
        """Create a store, or reopen one for ``--resume`` after checking it was made with ``settings``.

        ``path`` may be ``":memory:"`` (a campaign that keeps nothing). An existing store is refused
        without ``resume`` or ``overwrite`` (a campaign of days must not be lost to a forgotten flag);
        ``resume`` of a missing store starts it. Raises :class:`StressbotsError` (source ``--resume``)
        naming every setting that differs.
        """
        settings = json.loads(json.dumps(dict(settings)))  # what the store will hand back
        memory = str(path) == ":memory:"
        p = Path(str(path))
        if not memory and p.exists() and _is_empty(p):
            # made by a reader that looked too early, or by a campaign killed while creating it
            for suffix in ("", "-wal", "-shm"):
                Path(str(p) + suffix).unlink(missing_ok=True)
        if not memory and p.exists():
            if overwrite:
                for suffix in ("", "-wal", "-shm"):
                    Path(str(p) + suffix).unlink(missing_ok=True)
            elif not resume:
                n = cls._count_existing(p)
                raise StressbotsError(
                    f"{p} already holds a campaign ({n} trials); add --resume to continue it or --overwrite to start again",
                    source="--out",
                )
            else:
                return cls._reopen(p, settings)
        con = _connect(":memory:" if memory else p)
        try:
            if not memory:
                con.execute("PRAGMA journal_mode = WAL")
            con.execute("PRAGMA synchronous = NORMAL")
            cols = ", ".join(f"{n} {t}" for n, t in TRIAL_COLUMNS)
            con.execute("BEGIN")
            con.execute("CREATE TABLE campaign (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
            con.execute("CREATE TABLE cells (cell INTEGER PRIMARY KEY, label TEXT NOT NULL, params TEXT NOT NULL)")
            con.execute(f"CREATE TABLE trials ({cols})")
            meta = {"format": FORMAT, "settings": settings, "info": dict(info or {}), "created_utc": _utc_now()}
            con.executemany("INSERT INTO campaign VALUES (?, ?)", [(k, json.dumps(v, sort_keys=True)) for k, v in meta.items()])
            con.executemany("INSERT INTO cells VALUES (?, ?, ?)",
                            [(i, label, json.dumps(params, sort_keys=True)) for i, (label, params) in enumerate(cells)])
            con.execute("COMMIT")
        except BaseException:
            con.close()
            raise
        return cls(p, con, settings)

    @staticmethod
    def _count_existing(p: Path) -> int | str:
        try:
            con = _open_readonly(p)
            try:
                return int(con.execute("SELECT count(*) FROM trials").fetchone()[0])
            finally:
                con.close()
        except (StressbotsError, sqlite3.DatabaseError):
            return "unknown number of"

    @classmethod
    def _reopen(cls, p: Path, settings: Mapping[str, Any]) -> TrialStore:
        con = _open_readonly(p)
        try:
            row = con.execute("SELECT value FROM campaign WHERE key = 'settings'").fetchone()
            fmt = con.execute("SELECT value FROM campaign WHERE key = 'format'").fetchone()
        except sqlite3.DatabaseError as exc:
            con.close()
            raise StressbotsError(f"{p} is not a stressbots trial store ({exc})", source="--resume") from None
        if row is None or fmt is None or json.loads(fmt[0]) != FORMAT:
            con.close()
            raise StressbotsError(f"{p} is not a {FORMAT} trial store", source="--resume")
        diff = settings_differences(json.loads(row[0]), settings)
        if diff:
            con.close()
            raise StressbotsError(f"{p} was made with other settings: " + "; ".join(diff), source="--resume")
        con.execute("PRAGMA synchronous = NORMAL")
        return cls(p, con, settings)

    # -- use ---------------------------------------------------------------------------------------------

    def done(self) -> set[int]:
        """Numbers of the trials already in the store."""
        return {int(r[0]) for r in self._con.execute("SELECT trial FROM trials")}

    def __len__(self) -> int:
        return int(self._con.execute("SELECT count(*) FROM trials").fetchone()[0])

    def record(self, row: Mapping[str, Any]) -> bool:
        """Commit one finished trial (its own transaction). False when that trial was already there."""
        values = [_db_value(row.get(n)) for n in _NAMES]
        if values[_NAMES.index("finished_utc")] is None:
            values[_NAMES.index("finished_utc")] = _utc_now()
        cur = self._con.execute(
            f"INSERT OR IGNORE INTO trials ({', '.join(_NAMES)}) VALUES ({', '.join('?' * len(_NAMES))})", values
        )
        return cur.rowcount == 1

    def rows(self) -> list[dict[str, Any]]:
        """Every stored trial as a dict, in trial order."""
        return _rows(self._con)

    def cells(self) -> list[dict[str, Any]]:
        return _cells(self._con)

    def close(self) -> None:
        self._con.close()

    def __enter__(self) -> TrialStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _rows(con: sqlite3.Connection) -> list[dict[str, Any]]:
    cur = con.execute(f"SELECT {', '.join(_NAMES)} FROM trials ORDER BY trial")
    return [dict(zip(_NAMES, r, strict=True)) for r in cur]


def _cells(con: sqlite3.Connection) -> list[dict[str, Any]]:
    return [{"cell": c, "label": lab, "params": json.loads(p)} for c, lab,
            p in con.execute("SELECT cell, label, params FROM cells ORDER BY cell")]


def read_rows(path: Path | str) -> list[dict[str, Any]]:
    """The trials of a store (a finished, interrupted or running campaign), in trial order."""
    con = _open_readonly(path)
    try:
        return _rows(con)
    finally:
        con.close()


def read_settings(path: Path | str) -> dict[str, Any]:
    """``{"settings": ..., "info": ..., "format": ..., "created_utc": ..., "cells": [...]}`` of a store."""
    con = _open_readonly(path)
    try:
        out = {k: json.loads(v) for k, v in con.execute("SELECT key, value FROM campaign")}
        out["cells"] = _cells(con)
        return out
    finally:
        con.close()


def csv_text(rows: Iterable[Mapping[str, Any]], cells: Iterable[Mapping[str, Any]] = ()) -> str:
    """The trials as CSV (the :data:`TRIAL_COLUMNS` plus the cell's label; empty fields for NULL)."""
    labels = {int(c["cell"]): c["label"] for c in cells}
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(_NAMES + ("cell_label",))
    for r in rows:
        w.writerow([("" if r.get(n) is None else r.get(n)) for n in _NAMES] + [labels.get(int(r["cell"]), "")])
    return buf.getvalue()


def write_parquet(rows: Sequence[Mapping[str, Any]], cells: Iterable[Mapping[str, Any]], path: Path | str) -> Path:
    """Write the trials as a Parquet file (needs pyarrow, imported here only). Atomic, like every output."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise StressbotsError("Parquet needs pyarrow: pip install pyarrow (or export --format csv)", source="--format") from None
    from .outputs import write_bytes

    labels = {int(c["cell"]): c["label"] for c in cells}
    types = {"INTEGER": pa.int64(), "REAL": pa.float64(), "TEXT": pa.string()}
    fields = [pa.field(n, types[t.split()[0]]) for n, t in TRIAL_COLUMNS] + [pa.field("cell_label", pa.string())]
    columns = {n: [r.get(n) for r in rows] for n in _NAMES}
    columns["cell_label"] = [labels.get(int(r["cell"]), "") for r in rows]
    table = pa.table(columns, schema=pa.schema(fields))
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return write_bytes(path, sink.getvalue().to_pybytes())
