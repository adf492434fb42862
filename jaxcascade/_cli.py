"""Command-line entry point: `jaxcascade COMMAND ...`.

Each subcommand lives in the module of its concept, which exposes
`add_parser(subparsers)`; the parser's `func(args) -> int` runs it. Errors a user can
fix (bad values, missing files, unwritable folders) leave as one line on stderr and
exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# Modules that contribute a subcommand, in the order shown by --help.
_SUBCOMMANDS = [
    "jaxcascade._reproduce",
    "jaxcascade._montecarlo",
    "jaxcascade._fit",
    "jaxcascade._report",
    "jaxcascade._bench",
]


class CLIError(Exception):
    """A problem with the user's request; reported as one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's default prints the usage too: keep it to one line
        raise CLIError(f"{message} (see '{self.prog} --help')")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="jaxcascade",
        description="Identification of three-block cascade systems with backlash (Vörös 2016).",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    subparsers.required = True
    for name in _SUBCOMMANDS:
        importlib.import_module(name).add_parser(subparsers)
    return parser


def enable_float64() -> None:
    """Configure JAX for the CLI: float64 (recorded in result metadata; the library never
    flips it) and JAX's persistent compilation cache, so compiled code is reused across
    runs. The cache lives in `$JAXCASCADE_CACHE` (default `~/.cache/jaxcascade/xla`);
    `JAXCASCADE_CACHE=off` disables it."""
    import os

    import jax

    jax.config.update("jax_enable_x64", True)
    cache = os.environ.get("JAXCASCADE_CACHE", os.path.expanduser("~/.cache/jaxcascade/xla"))
    if cache.lower() not in ("", "off", "none", "0"):
        try:
            os.makedirs(cache, exist_ok=True)
        except OSError:
            return  # an unwritable cache only costs compile time
        jax.config.update("jax_compilation_cache_dir", cache)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
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


def check_positive(value: float, name: str) -> float:
    if not value > 0:
        raise CLIError(f"{name} must be positive, got {value}.")
    return value


def add_record_arguments(parser, *, scaling: str) -> None:
    """Options shared by the commands that read a measured record (`fit`, `loop`)."""
    parser.add_argument("--input", required=True, help="input column")
    parser.add_argument("--output", required=True, help="output column")
    parser.add_argument("--time", default=None, help="optional time column")
    parser.add_argument("--orders", default="2,2,2,2", help="declared nR,nL,r,p (default 2,2,2,2)")
    parser.add_argument("--decimate", type=int, default=1, help="anti-aliased decimation factor")
    parser.add_argument(
        "--scaling",
        default=scaling,
        choices=("none", "scale", "standard"),
        help=f"units the model is fitted in; estimates are also mapped back (default {scaling})",
    )


def parse_orders(text: str):
    """`--orders nR,nL,r,p` as `Orders`, or a CLIError naming the option."""
    from ._model import Orders

    try:
        return Orders.parse(text)
    except ValueError as error:
        raise CLIError(f"--orders: {error}") from None


def writable_folder(path) -> None:
    """Create `path` if needed and check it can be written, before any work starts."""
    import os
    import pathlib
    import tempfile

    folder = pathlib.Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise CLIError(
            f"cannot write to output folder '{folder}' ({error.strerror or error}); "
            "choose another with --out."
        ) from None
    if not os.access(folder, os.W_OK):
        raise CLIError(f"cannot write to output folder '{folder}'; choose another with --out.")


if __name__ == "__main__":
    sys.exit(main())
