"""Writing results: atomic files, output folders and the provenance every run records.

Every file stressbots writes goes through here, so that (a) a crash or Ctrl-C never leaves a half-written
file where a good one was, and (b) no output ever overwrites one of the user's input files.
"""

from __future__ import annotations

import json
import math
import os
import platform
import re
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .errors import StressbotsError


def versions() -> dict[str, str]:
    """Versions of stressbots, Python and the numerical libraries, recorded in every output."""
    import numpy
    import scipy

    from . import __version__

    out = {"stressbots": __version__, "python": platform.python_version(), "numpy": numpy.__version__, "scipy": scipy.__version__}
    try:
        import shapely

        out["shapely"] = shapely.__version__
    except ImportError:  # pragma: no cover - shapely is a runtime dependency
        pass
    return out


def provenance(seed: int | None = None, **extra: Any) -> dict[str, Any]:
    """The ``"provenance"`` block of an output: seed (if any) and versions."""
    block: dict[str, Any] = {"versions": versions()}
    if seed is not None:
        block["seed"] = int(seed)
    block.update(extra)
    return block


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve()
    except OSError:
        return False


def check_not_input(path: Path, inputs: Iterable[Path | str | None], *, option: str = "--out") -> None:
    """Refuse to write ``path`` if it is one of the user's input files."""
    for src in inputs:
        if src is not None and _same_file(Path(path), Path(src)):
            raise StressbotsError(f"would overwrite the input file {src}; choose another path", source=option)


def prepare_dir(path: Path | str, *, inputs: Iterable[Path | str | None] = (), option: str = "--out",
                files: Iterable[str] = ()) -> Path:
    """Create an output folder (and parents) and check that it can be written, before any computation.

    Refuses a path that is an input, an existing file, under a regular file, or not writable, with one
    :class:`StressbotsError` naming the path; with ``files`` (the names the command will write there) also
    any of them that is an input (:func:`check_not_input`). Hidden temporary files that a killed earlier
    run left behind (:func:`clean_stale_temporaries`) are removed.
    """
    out = Path(path)
    inputs = list(inputs)
    for src in inputs:
        if src is not None and _same_file(out, Path(src)):
            raise StressbotsError(f"{out} is the input file {src}; give a folder for the outputs", source=option)
    if out.exists() and not out.is_dir():
        raise StressbotsError(f"{out} exists and is not a folder", source=option)
    blocker = _file_ancestor(out)
    if blocker is not None:
        raise StressbotsError(f"cannot create folder {out}: {blocker} is a file, not a folder", source=option)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StressbotsError(f"cannot create folder {out}: {exc.strerror or exc}", source=option) from None
    _probe_writable(out, option)
    clean_stale_temporaries(out)
    for name in files:
        check_not_input(out / name, inputs, option=option)
    return out


def prepare_file(path: Path | str, *, inputs: Iterable[Path | str | None] = (), option: str = "--out") -> Path:
    """Check, before any computation, that a single output file can be written at ``path``.

    The path must not be an input or an existing folder; its folder is created if needed and must be
    writable. The file itself is written later (atomically) by :func:`write_bytes`.
    """
    target = Path(path)
    check_not_input(target, inputs, option=option)
    if target.is_dir():
        raise StressbotsError(f"{target} is a folder; give a file name", source=option)
    prepare_dir(target.parent if str(target.parent) else Path("."), option=option)
    return target


def _file_ancestor(path: Path) -> Path | None:
    """The first existing ancestor of ``path`` (or ``path``'s parent chain) that is not a folder."""
    for p in [path, *path.parents]:
        if p.exists():
            return None if p.is_dir() else (p if p != path else None)
    return None


def _probe_writable(folder: Path, option: str) -> None:
    try:
        fd, probe = tempfile.mkstemp(prefix=f".probe.{_TMP_TAG}{os.getpid()}.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise StressbotsError(f"cannot write into folder {folder}: {exc.strerror or exc}", source=option) from None
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:  # pragma: no cover - the folder was writable a moment ago
        pass


#: Marks stressbots' temporary files: ``.NAME.stressbots-PID.XXXXXXXX.tmp`` (PID of the writer).
_TMP_TAG = "stressbots-"
_TMP_NAME = re.compile(r"^\..+\.stressbots-(\d+)\.[A-Za-z0-9_]+\.tmp$")


def clean_stale_temporaries(folder: Path) -> list[Path]:
    """Remove hidden temporary files of :func:`write_bytes` whose writer is gone.

    A process killed with SIGKILL cannot remove its temporary file; the next run in the same folder
    does. Only files named like stressbots' own (``.NAME.stressbots-PID.XXXXXXXX.tmp``) are touched,
    and only when no process with that id is alive (another run may be writing right now).
    """
    removed: list[Path] = []
    try:
        entries = list(folder.glob(f".*.{_TMP_TAG}*.tmp"))
    except OSError:
        return removed
    for f in entries:
        m = _TMP_NAME.match(f.name)
        if m is None or _alive(int(m.group(1))):
            continue
        try:
            f.unlink()
            removed.append(f)
        except OSError:
            continue
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def write_bytes(path: Path | str, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename).

    The temporary file is hidden and carries the writer's process id (``.NAME.stressbots-PID.XXXXXXXX.tmp``)
    so that a later run can remove it if this process is killed. A failure to write is a :class:`StressbotsError`
    naming the path.
    """
    target = Path(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.is_dir():
            raise StressbotsError(f"{target} is a folder; cannot write a file there", source="--out")
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.{_TMP_TAG}{os.getpid()}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise StressbotsError(f"cannot write {target}: {exc.strerror or exc}", source="--out") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644 & ~_umask())  # mkstemp makes 0600; results are ordinary readable files
        os.replace(tmp, target)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise StressbotsError(f"cannot write {target}: {exc.strerror or exc}", source="--out") from None
        raise
    return target


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text(path: Path | str, text: str) -> Path:
    return write_bytes(path, text.encode("utf-8"))


def _jsonable(obj: Any) -> Any:
    """Convert numpy scalars/arrays and tuples; refuse NaN/inf (JSON has none) by writing null."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if math.isfinite(f) else None
    return obj


def to_json(obj: Any) -> str:
    """JSON text for results: numpy converted, non-finite floats written as null, stable indentation."""
    return json.dumps(_jsonable(obj), indent=2, allow_nan=False) + "\n"


def write_json(path: Path | str, obj: Any) -> Path:
    return write_text(path, to_json(obj))


def figure_bytes(fig, fmt: str = "png", **kwargs: Any) -> bytes:
    """Render a matplotlib figure to bytes (default PNG, 120 dpi, tight) and close it."""
    import io

    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    kwargs.setdefault("dpi", 120)
    kwargs.setdefault("bbox_inches", "tight")
    try:
        fig.savefig(buf, format=fmt, **kwargs)
    finally:
        plt.close(fig)
    return buf.getvalue()


def save_figure(fig, path: Path | str, **kwargs: Any) -> Path:
    """Save a matplotlib figure atomically (format from the suffix) and close it."""
    target = Path(path)
    return write_bytes(target, figure_bytes(fig, target.suffix.lstrip(".") or "png", **kwargs))
