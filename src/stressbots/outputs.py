"""Writing results: atomic files, output folders and the provenance every run records.

Every file stressbots writes goes through here, so that (a) a crash or Ctrl-C never leaves a half-written
file where a good one was, and (b) no output ever overwrites one of the user's input files.
"""

from __future__ import annotations

import json
import math
import os
import platform
import tempfile
from pathlib import Path
from typing import Any, Iterable

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


def prepare_dir(path: Path | str, *, inputs: Iterable[Path | str | None] = (), option: str = "--out") -> Path:
    """Create an output folder (and parents). Refuses a path that is an existing file or an input."""
    out = Path(path)
    for src in inputs:
        if src is not None and _same_file(out, Path(src)):
            raise StressbotsError(f"is the input file {src}; give a folder for the outputs", source=option)
    if out.exists() and not out.is_dir():
        raise StressbotsError(f"{out} exists and is not a folder", source=option)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StressbotsError(f"cannot create folder {out}: {exc.strerror}", source=option) from None
    return out


def write_bytes(path: Path | str, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644 & ~_umask())  # mkstemp makes 0600; results are ordinary readable files
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
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
