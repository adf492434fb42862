"""The command line, `jaxcascade COMMAND ...`: the only place that knows argparse.

One module per command (`_reproduce`, `_sweep`, `_fit`, `_loop`, `_simulate`, `_bench`),
each with `add_parser(subparsers)`; the parser's `func(args) -> int` runs it. Domain code raises
`ValueError` for problems a user can fix; here every such error (and `CLIError`,
`OSError`) leaves as one line on stderr with exit code 2, never a traceback.
"""

from __future__ import annotations

import os
import sys

# Each command module imports JAX, NumPy and pandas inside the function that runs it, so
# `--help` answers at once (tests/test_help.py holds that no help imports JAX).
from .._version import __version__
from . import _bench, _fit, _loop, _reproduce, _simulate, _sweep
from ._common import CLIError, Parser, examples

# Commands in the order shown by --help.
_COMMANDS = (_reproduce, _sweep, _fit, _loop, _simulate, _bench)


def build_parser() -> Parser:
    parser = Parser(
        prog="jaxcascade",
        description="Identification of three-block cascade systems with backlash (Vörös 2016). "
        "'jaxcascade COMMAND --help' describes a command, its options and examples.",
        epilog=examples(
            "jaxcascade reproduce --example 1",
            "jaxcascade sweep --example 1 --snr 25 --n 4000 --realisations 100 "
            "--estimator literal,robust --out runs/quickstart.parquet --plots runs/quickstart "
            "--overwrite",
            "jaxcascade fit record.csv --input u --output y --decimate 8",
            "jaxcascade loop train.csv --validate valid.csv --input u --output y "
            "--report runs/loop",
            "jaxcascade simulate runs/loop/model.json test.csv --input u --output y",
            "jaxcascade bench --estimator robust --system example1 --json",
        ),
    )
    parser.add_argument(
        "--version",
        action="version",
        version=f"jaxcascade {__version__}",
        help="print the installed version and exit",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    subparsers.required = True
    for command in _COMMANDS:
        command.add_parser(subparsers)
    return parser


def enable_float64() -> None:
    """Configure JAX for the CLI: float64 (recorded in result metadata; the library never
    flips it) and JAX's persistent compilation cache, so compiled code is reused across
    runs. The cache lives in `$JAXCASCADE_CACHE` (default `~/.cache/jaxcascade/xla`);
    `JAXCASCADE_CACHE=off` disables it. Every program is kept, however quickly it
    compiled: a loop compiles about a hundred programs of well under half a second each,
    which JAX's default threshold would compile again in every run, and they add little
    to the folder (`results/loop_speed.md`)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    cache = os.environ.get("JAXCASCADE_CACHE", os.path.expanduser("~/.cache/jaxcascade/xla"))
    if cache.lower() not in ("", "off", "none", "0"):
        try:
            os.makedirs(cache, exist_ok=True)
        except OSError:
            return  # an unwritable cache only costs compile time
        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        enable_float64()
        return int(args.func(args) or 0)
    except (CLIError, ValueError, OSError) as error:
        message = str(error).strip().splitlines()[0] if str(error).strip() else repr(error)
        print(f"jaxcascade: error: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            "jaxcascade: interrupted; completed chunks are kept, rerun to resume.", file=sys.stderr
        )
        return 130


__all__ = ["CLIError", "build_parser", "enable_float64", "main"]
