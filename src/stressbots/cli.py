"""The ``stressbots`` command line: a thin layer over the library.

Each command validates its inputs through the library (which raises
:class:`~stressbots.errors.StressbotsError` for anything the user got wrong), calls the pure computation,
and writes results through :mod:`stressbots.outputs`. :func:`main` turns every user error, including bad
options, into one ``error:`` line on stderr and exit status 2, with no traceback.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console

from .errors import StressbotsError

app = typer.Typer(
    name="stressbots",
    help=(
        "Plan and control groups of stress-engineered MEMS microrobots (MicroStressBots) that all share "
        "one global voltage signal.\n\n"
        "Start with `stressbots demo`. Scenario files are TOML (see README, 'Scenario files'); lengths in "
        "um, times in s, voltages in V, file angles in degrees."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",
)

# Results go to stdout; progress and notes to stderr so that `--json` output stays clean.
out = Console()
err = Console(stderr=True)


def scenario_arg(path: Path):
    """Load a scenario given on the command line (errors name the file and field)."""
    from .scenario import load

    return load(path)


def _show_version(value: bool) -> None:
    if value:
        from .outputs import versions

        print(" ".join(f"{k} {v}" for k, v in versions().items()))
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_show_version, is_eager=True, help="Print the versions and exit."
    ),
) -> None:
    """Plan and control groups of MEMS microrobots that share one global voltage signal."""


@app.command()
def demo(
    out_dir: Path = typer.Option(Path("stressbots-demo"), "--out", help="Folder for the demo's outputs."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print only the final summary."),
) -> None:
    """Run the main job end to end on the built-in 4-robot scenario.

    Today: analyse the built-in voltage design (accessible control states, control matrix, primitives)
    and synthesise the waveform of every primitive.
    """
    from . import demo as demo_mod

    demo_mod.run_demo(out_dir, console=out, quiet=quiet)


def _click_base(name: str) -> type[BaseException]:
    """The click exception class ``name`` as used by this Typer (newer Typers vendor their own click)."""
    for cls in typer.BadParameter.__mro__:
        if cls.__name__ == name:
            return cls
    raise RuntimeError(f"typer has no {name}")  # pragma: no cover


_UsageError = _click_base("UsageError")
_ClickException = _click_base("ClickException")


def main(argv: Optional[list[str]] = None) -> None:
    """Console-script entry point: run the CLI, mapping user errors to ``error:`` + exit 2."""
    command = typer.main.get_command(app)
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        code = command.main(args=args, prog_name="stressbots", standalone_mode=False)
    except StressbotsError as exc:
        print(f"error: {exc.message}", file=sys.stderr)
        sys.exit(2)
    except _UsageError as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # bare `stressbots`: Typer has shown the help
            sys.exit(0)
        msg = " ".join(exc.format_message().split())
        where = f"stressbots {exc.ctx.info_name}" if exc.ctx is not None and exc.ctx.parent is not None else "stressbots"
        print(f"error: {msg} (see '{where} --help')", file=sys.stderr)
        sys.exit(2)
    except _ClickException as exc:
        print(f"error: {' '.join(exc.format_message().split())}", file=sys.stderr)
        sys.exit(2)
    except (typer.Abort, KeyboardInterrupt):
        print("error: interrupted", file=sys.stderr)
        sys.exit(130)
    except BrokenPipeError:  # e.g. `stressbots states x.toml | head`
        sys.exit(0)
    if isinstance(code, int) and code != 0:
        sys.exit(code)
