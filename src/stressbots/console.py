"""Console presentation: the rich tables and progress bars of the command line.

Everything that prints for people lives here, apart from the pure computation: the voltage analysis
as tables (:func:`render_analysis`), a waveform's segments (:func:`render_waveform`), a closed-loop
result (:func:`robot_table`) and the main job's progress and summary (:class:`RichJobObserver`, an
observer of :func:`stressbots.pipeline.run_job`). The CLI and the demo use it; library modules never
import it, so the flow is cli -> demo -> pipeline -> library, with this module beside them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from rich.console import Console

from .pipeline import JobObserver

__all__ = ["render_analysis", "render_waveform", "robot_table", "verdict_text", "RichJobObserver"]


def _bits(state, n: int) -> str:
    return (" " if n <= 16 else "").join(str(int(x)) for x in state)


def render_analysis(analysis, console: Console, *, title: str | None = None, max_rows: int = 32) -> None:
    """Print a control analysis as rich tables: robots, verdict, states, control matrix, primitives."""
    a = analysis
    head = f"{title}: " if title else ""
    n = a.n
    line = _liner(console)
    if a.is_string:
        line(f"[bold]{head}{n} robot{'s' if n != 1 else ''}, STRING[/bold]: order D_1..D_{n} = {', '.join(a.order)}")
        line(f"Lemma 1: {a.count} accessible control states, the primitives P_0..P_{n} (P_k: D_1..D_k arm down).")
    else:
        line(f"[bold]{head}{n} robot{'s' if n != 1 else ''}, not STRING[/bold]:")
        for r in a.reasons:
            line(f"  - {r}")
        line(f"{a.count} accessible control states (exhaustive search); each one is a primitive, P0 = all arms up.")
    e = a.electrodes
    line(
        f"Limits: levels in [0, {e.max_V:g}] V, margin_V {e.margin_V:g} V; drive band [{e.drive_low_V:g}, "
        f"{e.drive_high_V:g}] V at {e.drive_frequency_hz:g} Hz; {len(a.levels)} admissible level cells."
    )
    _heading(console, "Robots (scenario order)")
    console.print(_robots_table(a, max_rows))
    _heading(console, f"Accessible control states: {a.count} (1 = arm down = turning; robots in scenario order)")
    console.print(_states_table(a, max_rows))
    if n <= max_rows:
        _heading(
            console,
            "Control matrix M (1 = the robot turns under the primitive"
            + ("; rows D_1..D_n)" if a.is_string else "; rows in scenario order)"),
        )
        console.print(_matrix_table(a))
    _heading(console, "Primitives (reach the arm state with Holds, then Drive)")
    console.print(_primitives_table(a, max_rows))


def _liner(console: Console):
    def line(text: str) -> None:
        console.print(text, soft_wrap=True, highlight=False)

    return line


def _heading(console: Console, text: str) -> None:
    console.print()
    console.print(f"[bold]{text}[/bold]", soft_wrap=True, highlight=False)


def _robots_table(a, max_rows: int):
    from rich.table import Table

    rank = {i: k for k, i in enumerate(a.order_index)} if a.is_string else {}
    t = Table()
    t.add_column("robot")
    t.add_column("snap-down V_d (V)", justify="right")
    t.add_column("release V_u (V)", justify="right")
    if a.is_string:
        t.add_column("order", justify="right")
    for i, nm in enumerate(a.names[:max_rows]):
        row = [nm, f"{a.snap_down_V[i]:g}", f"{a.release_V[i]:g}"]
        if a.is_string:
            row.append(f"D_{rank[i] + 1}")
        t.add_row(*row)
    if a.n > max_rows:
        t.add_row(f"... {a.n - max_rows} more", "", "", *([""] if a.is_string else []))
    return t


def _states_table(a, max_rows: int):
    from rich.table import Table

    t = Table()
    t.add_column("#", justify="right")
    t.add_column(" ".join(a.names) if a.n <= 16 else "arm states", no_wrap=True)
    t.add_column("primitive")
    for k, row in enumerate(a.accessible_states[:max_rows]):
        # STRING: the state with j arms down is P_j; otherwise the sorted states are P0, P1, ...
        t.add_row(str(k + 1), _bits(row, a.n), f"P{int(row.sum())}" if a.is_string else f"P{k}")
    if a.count > max_rows:
        t.add_row("...", f"{a.count - max_rows} more (see --json)", "")
    return t


def _matrix_table(a):
    from rich.table import Table

    n_prims = a.primitive_states.shape[0]
    k_cols = min(n_prims, 24)
    more = ["..."] if n_prims > k_cols else []
    rows_lbl = [f"D_{i + 1} {a.order[i]}" for i in range(a.n)] if a.is_string else list(a.names)
    t = Table()
    t.add_column("")
    for k in range(k_cols):
        t.add_column(f"P{k}", justify="right")
    if more:
        t.add_column("...")
    for i in range(a.n):
        t.add_row(rows_lbl[i], *[str(int(x)) for x in a.control_matrix[i, :k_cols]], *more)
    return t


def _primitives_table(a, max_rows: int):
    from rich.table import Table

    n, n_prims = a.n, a.primitive_states.shape[0]
    t = Table()
    t.add_column("primitive")
    t.add_column("turning (arm down)")
    if a.is_string:
        t.add_column("Hold from below (V)", justify="right")
        t.add_column("Hold from above (V)", justify="right")
    for p in (a.primitive_at(k) for k in range(min(n_prims, max_rows))):
        row = [p.name, ", ".join(p.turning) or "none (all straight)"]
        if a.is_string:
            up, down = a.raise_levels_V[p.index], a.release_levels_V[p.index]
            row += [f"{up:g}" if np.isfinite(up) else ("-" if p.index == 0 else "2 levels (tie)"),
                    f"{down:g}" if np.isfinite(down) else ("-" if p.index == n else "2 levels (tie)")]
        t.add_row(*row)
    if n_prims > max_rows:
        t.add_row(f"... {n_prims - max_rows} more", "", *(["", ""] if a.is_string else []))
    return t


def render_waveform(waveform, console: Console, *, title: str = "Waveform") -> None:
    """Print a waveform's segments as a table (levels in V, durations in s)."""
    from rich.table import Table

    from .waveform import Hold

    console.print(f"[bold]{title}[/bold]", soft_wrap=True, highlight=False)
    t = Table()
    t.add_column("#", justify="right")
    t.add_column("segment")
    t.add_column("level(s) (V)", justify="right")
    t.add_column("duration (s)", justify="right")
    for k, seg in enumerate(waveform):
        if isinstance(seg, Hold):
            t.add_row(str(k), "Hold", f"{seg.volts:g}", f"{seg.duration_s:g}")
        else:
            t.add_row(str(k), "Drive", f"{seg.low_V:g} .. {seg.high_V:g}", f"{seg.duration_s:g}")
    console.print(t)


def robot_table(names, res):
    """A rich table of a closed-loop result, one row per robot: docked, placement and heading error."""
    from rich.table import Table

    t = Table()
    for col, just in (("robot", "left"), ("docked", "left"), ("placement error (um)", "right"), ("heading error (deg)", "right")):
        t.add_column(col, justify=just)  # type: ignore[arg-type]
    for i, name in enumerate(names):
        t.add_row(name, "yes" if res.docked[i] else "no", f"{res.placement_error_um[i]:.3g}", f"{res.heading_error_deg[i]:.3g}")
    return t


def verdict_text(result_doc: dict[str, Any]) -> str:
    """``assembled`` or ``not assembled: <reason>``."""
    from .report import outcome_text

    return outcome_text(result_doc)


class RichJobObserver(JobObserver):
    """Shows the main job on a console: the analysis tables, progress bars (stderr, on a terminal) and
    the readable summary (stdout). ``quiet`` shows nothing: only errors reach the user.

    Implements :class:`stressbots.pipeline.JobObserver`.
    """

    def __init__(self, console: Console | None = None, err_console: Console | None = None, *, quiet: bool = False,
                 show_analysis: bool = True):
        self.console = console or Console()
        self.err_console = err_console or Console(stderr=True)
        self.quiet = quiet
        self.show_analysis = show_analysis
        self._bar: Any = None
        self._tasks: dict[str, Any] = {}

    # -- the job's life
    def analysed(self, scenario, analysis, source: str | None) -> None:
        if self.show_analysis and not self.quiet:
            render_analysis(analysis, self.console, title=f"{scenario.name}" + (f" ({source})" if source else ""))
            self.console.print()

    def __enter__(self) -> RichJobObserver:
        from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

        self._bar = Progress(
            SpinnerColumn(), TextColumn("{task.description:<22}"), BarColumn(), TextColumn("{task.fields[info]}"),
            TimeElapsedColumn(), console=self.err_console, disable=self.quiet or not self.err_console.is_terminal,
            transient=False,
        )
        self._bar.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)
            self._bar = None

    def stage(self, name: str, *, total: float | None = None, completed: float | None = None, info: str | None = None,
              advance: float | None = None) -> None:
        """Start (first call) or update the progress of stage ``name``."""
        if self._bar is None:
            return
        if name not in self._tasks:
            self._tasks[name] = self._bar.add_task(name, total=total, info=info or "")
            return
        kwargs: dict[str, Any] = {}
        if total is not None:
            kwargs["total"] = total
        if completed is not None:
            kwargs["completed"] = completed
        if info is not None:
            kwargs["info"] = info
        if advance is not None:
            kwargs["advance"] = advance
        self._bar.update(self._tasks[name], **kwargs)

    def finished(self, summary) -> None:
        """Print the job's summary (a :class:`stressbots.pipeline.JobSummary`)."""
        if self.quiet:
            return
        print_job_summary(self.console, summary)


def print_job_summary(console: Console, summary) -> None:
    """The main job's readable summary: plan, closed loop, per-robot table, verdict, files."""
    scenario, plan_summary, res, doc = summary.scenario, summary.plan_summary, summary.result, summary.document
    out, report_bytes, wall, extra_lines = summary.out_dir, summary.report_bytes, summary.wall_s, summary.lines
    docked = int(np.sum(res.docked))
    verdict = verdict_text(doc)
    s = plan_summary
    console.print(
        f"[bold]Plan[/bold]: {s['structure']} in {s['duration_s']:.1f} s, {s['steps']} steps (lower bound {s['lower_bound_s']:.1f} s, "
        f"efficiency {s['efficiency']:.2f}); replayed independently: ok",
        highlight=False, soft_wrap=True,
    )
    console.print(f"[bold]Closed loop[/bold] on the simulated plant, seed {res.seed}: {res.duration_s:.1f} s simulated, "
                  f"{res.replans} re-plans", highlight=False, soft_wrap=True)
    console.print(robot_table(scenario.names, res))
    style = "bold green" if res.success else "bold red"
    console.print(f"[{style}]{verdict}[/{style}]", highlight=False, soft_wrap=True)
    console.print(
        f"{docked}/{scenario.n} docked, shape error {res.shape_error_rms_um:.3g} um RMS after the best rigid alignment "
        f"(rotation {res.shape_rotation_deg:.1f} deg); {len(doc.get('events', []))} controller events, "
        f"{len(doc.get('plant_events', []))} plant events",
        highlight=False, soft_wrap=True,
    )
    for text in extra_lines:
        console.print(text, highlight=False, soft_wrap=True)
    console.print(
        f"wrote {out / 'report.html'} ({report_bytes / 1e6:.2f} MB, opens offline), result.json, plan.json, states.json, "
        f"waveform.json, waveform.npy and the pictures to {out} in {wall:.1f} s",
        highlight=False, soft_wrap=True,
    )
