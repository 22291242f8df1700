"""The ``suspid`` command line.

User mistakes (a :class:`~suspid.errors.SuspidError`) print one line on stderr
and exit with code 2; ``--debug`` shows the traceback instead. Ctrl-C exits
with code 130 and keeps what is already in the run ledger.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import List, Optional

import click
import typer
from rich.console import Console
from rich.table import Table

import suspid
from suspid.errors import SuspidError

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Identify train suspension parameters from on-track accelerations.")
console = Console()
err_console = Console(stderr=True)

ConfigArg = typer.Argument(..., help="YAML config file.", show_default=False)
SetOpt = typer.Option(None, "--set", help="Override a config value: key.path=value (repeatable).")


def _version(value: bool) -> None:
    if value:
        console.print(f"suspid {suspid.__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit."),
          debug: bool = typer.Option(False, "--debug", help="Show tracebacks of errors.")) -> None:
    """suspid: EGO identification of train suspension parameters (see README)."""


@app.command()
def plugins() -> None:
    """List every plugin: kind, name, entry point, distribution, version, module."""
    from suspid import registry

    rows, failures = registry.plugins()
    if not console.is_terminal:
        console.width = 240  # keep rows whole when piped
    table = Table(title="suspid plugins")
    for col in ("kind", "name", "entry point", "distribution", "version", "module"):
        table.add_column(col)
    for r in rows:
        table.add_row(r.kind, r.name, r.plugin.name, r.plugin.distribution or "-", r.plugin.version or "-",
                      f"{r.cls.__module__}.{r.cls.__qualname__}")
    for f in failures:
        table.add_row("[red]broken[/red]", "-", f.name, f.distribution or "-", f.version or "-",
                      f"{f.module}: {f.error}")
    console.print(table)


@app.command()
def validate(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt) -> None:
    """Check a config (plugins, options, parameters, data files); exit 0 when valid."""
    from suspid.config import load_config

    cfg = load_config(config, set_ or [])
    console.print(f"{config}: valid (simulator {cfg.simulator.plugin}, objective {cfg.objective.plugin}, "
                  f"surrogate {cfg.surrogate.plugin})")


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point; returns (and exits with) the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    warnings.showwarning = _show_warning
    try:
        app(args=argv, prog_name="suspid", standalone_mode=False)
        code = 0
    except SuspidError as exc:
        if debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        code = 2
    except click.exceptions.Exit as exc:
        code = exc.exit_code
    except click.ClickException as exc:
        exc.show()
        code = exc.exit_code
    except (KeyboardInterrupt, click.exceptions.Abort):
        err_console.print("interrupted: finished evaluations are kept in the run ledger; run again to resume")
        code = 130
    sys.exit(code)


if __name__ == "__main__":  # python -m suspid.cli
    main()
