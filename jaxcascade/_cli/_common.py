"""What the commands share: the one-line error, options that read a record, parsers of
option values, and the check that an output folder can be written (`strict_json`, the
package's JSON writer, re-exported from `_json`)."""

from __future__ import annotations

import argparse
import math
import os
import pathlib
import tempfile

from .._json import strict_json as strict_json


class CLIError(Exception):
    """A problem with the user's request; reported as one line, exit code 2."""


class _Formatter(argparse.HelpFormatter):
    # Text laid out by hand (the examples that end each --help) is kept as written;
    # one-paragraph descriptions are wrapped as usual.
    def _fill_text(self, text, width, indent):
        if "\n" in text:
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


class Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _Formatter)
        super().__init__(*args, **kwargs)

    def error(self, message):  # argparse's default prints the usage too: keep it to one line
        raise CLIError(f"{message} (see '{self.prog} --help')")


# The record spec, documented once: the help of every positional or option that names a
# record file (fit's DATA, loop's TRAIN, --validate, --test) ends with it.
RECORD_SPEC = (
    "FILE[:INPUT,OUTPUT[:START:STOP]]: FILE a .csv, .tsv or .txt (delimiter, decimal comma "
    "and a missing header detected), .parquet or .mat file (v4 to v7.3); INPUT,OUTPUT its "
    "signals (header names, 0-based column indices or MAT variables, row or column "
    "vectors), which override --input/--output; START:STOP the samples of the file as "
    "stored (0-based, before decimation, a Python slice, either may be empty), e.g. "
    "DATAUNIF.MAT:u12,z12:0:300 or DATAUNIF.MAT:u11,z11::300; a path that exists as given "
    "is a file even if it holds ':'"
)


def add_signal_arguments(parser, *, required: bool = False) -> None:
    """The options that name a record's signals, its sample period and units (`fit`,
    `loop`, `simulate`)."""
    parser.add_argument(
        "--input",
        required=required,
        help="input signal: a column name, a 0-based column index or a MAT variable "
        "(needed unless every record spec names its signals)",
    )
    parser.add_argument(
        "--output",
        required=required,
        help="output signal, as --input",
    )
    parser.add_argument("--time", default=None, help="optional time column (or MAT variable)")
    parser.add_argument(
        "--ts",
        type=float,
        default=None,
        metavar="SECONDS",
        help="sample period of records without a time column (with one, they must agree "
        "within 1 %%); records of one command must share their period",
    )
    parser.add_argument(
        "--units",
        default=None,
        metavar="INPUT_UNIT,OUTPUT_UNIT",
        help="physical units of input and output, kept with the record (e.g. V,mm)",
    )


def add_record_arguments(parser, command: str, *, required: bool = False) -> None:
    """Options shared by the commands that read a measured record (`fit`, `loop`, named
    by `command`), with the measured-data defaults of `_defaults`; their records are
    record specs (`RECORD_SPEC`), read by `read_record(spec, **record_options(args))`;
    `--orders` is parsed as the option is read (`orders_option`)."""
    from .. import _defaults

    scaling = _defaults.SCALING
    add_signal_arguments(parser, required=required)
    parser.add_argument(
        "--detrend",
        default=_defaults.DETREND,
        choices=("none", "mean", "linear"),
        help="remove the mean or the least-squares line from input and output of every "
        f"record, as MATLAB's detrend, before decimation and scaling (default "
        f"{_defaults.DETREND})",
    )
    parser.add_argument(
        "--orders",
        default=_defaults.ORDERS,
        type=orders_option(command),
        help=f"declared nR,nL,r,p (default {_defaults.ORDERS}; at most 8,8,16,16, and the "
        "record needs "
        "10 samples per parameter)",
    )
    parser.add_argument(
        "--decimate",
        type=int,
        default=_defaults.DECIMATE,
        help=f"anti-aliased decimation factor (default {_defaults.DECIMATE})",
    )
    parser.add_argument(
        "--scaling",
        default=scaling,
        choices=("none", "scale", "standard", "auto"),
        help="units the model is fitted in: none, scale (divide by the std), standard "
        "(centre and scale), auto (scale, or standard when the input has fewer than 5 %% of "
        "its samples on one side of zero); estimates are also mapped back "
        f"(default {scaling})",
    )


def record_options(args) -> dict:
    """`read_record`'s settings from the record options (`add_record_arguments`)."""
    units = [None, None]
    if args.units is not None:
        units = [part.strip() or None for part in args.units.split(",")]
        if len(units) != 2:
            raise CLIError(f"--units takes INPUT_UNIT,OUTPUT_UNIT, got {args.units!r}.")
    if args.ts is not None and not (math.isfinite(args.ts) and args.ts > 0):
        raise CLIError(f"--ts must be a positive number of seconds, got {args.ts}.")
    return dict(
        input_column=args.input,
        output_column=args.output,
        time_column=args.time,
        sample_period=args.ts,
        input_unit=units[0],
        output_unit=units[1],
        detrend=args.detrend,
        decimate=args.decimate,
    )


def parse_orders(text: str, command: str | None = None):
    """`--orders nR,nL,r,p` as `Orders`, or a CLIError naming the option. `command`: a
    command that declares the straight backlash only (`fit`, `loop`), which refuses a
    fifth number (the branch degree) in one sentence. Imports no JAX (`_system._orders`)."""
    from .._system._orders import Orders

    try:
        orders = Orders.parse(text)
    except ValueError as error:
        raise CLIError(f"--orders: {error}") from None
    if command is not None and orders.degree > 1:
        raise CLIError(
            f"--orders: jaxcascade {command} declares the straight backlash, four numbers "
            f"nR,nL,r,p, got {text!r}; curved branches are the loop's effect "
            "general_backlash, and jaxcascade sweep fits them."
        )
    return orders


def orders_option(command: str | None = None):
    """An argparse type: `--orders` parsed as it is read (`parse_orders`), so a command
    gets `Orders` in its arguments."""

    def parse(text: str):
        return parse_orders(text, command)

    return parse


def span_option(option: str):
    """An argparse type: `START:STOP` as two integers (samples of the file as stored)."""

    def parse(text: str) -> tuple[int, int]:
        try:
            start, stop = (int(part) for part in text.split(":"))
        except ValueError:
            raise CLIError(f"{option} takes START:STOP in samples, got {text!r}.") from None
        return start, stop

    return parse


def number_list(kind, option: str):
    """An argparse type: comma-separated numbers of `kind`, at least one."""

    def parse(text: str):
        try:
            values = [kind(part) for part in text.split(",") if part.strip()]
        except ValueError:
            raise CLIError(f"{option} takes comma-separated numbers, got {text!r}.") from None
        if not values:
            raise CLIError(f"{option} needs at least one value.")
        return values

    return parse


def name_list(text: str) -> list[str]:
    """Comma-separated names (an argparse type too)."""
    return [part.strip() for part in text.split(",") if part.strip()]


def estimator_help() -> str:
    """One line per registered estimator, for `--estimator` help texts."""
    from .._names import ESTIMATORS  # the names without importing JAX

    return "; ".join(f"{name}: {summary}" for name, summary in ESTIMATORS.items()) + (
        "; or a user's estimator, registered by its package's entry point (group "
        "jaxcascade.estimators)"
    )


def kind_with_settings(option: str):
    """An argparse type: `KIND` or `KIND:SETTINGS`, the settings a TOML inline table's
    body (`ar:poles = [0.9, 0.5]`, `outliers:fraction = 0.02, size = 10`); returns
    `(kind, {setting: value})`."""

    def parse(text: str):
        import tomllib

        kind, _, body = text.partition(":")
        kind = kind.strip()
        if not kind:
            raise CLIError(f"{option} takes KIND or KIND:SETTINGS, got {text!r}.")
        if not body.strip():
            return kind, {}
        try:
            settings = tomllib.loads(f"settings = {{{body}}}")["settings"]
        except tomllib.TOMLDecodeError:
            raise CLIError(
                f"{option}: the settings {body.strip()!r} are not a TOML inline table's "
                "body (e.g. poles = [0.9], dof = 3)."
            ) from None
        return kind, settings

    return parse


def kind_help(names: dict) -> str:
    """One entry per registered kind, for `--input-kind` and `--noise` help texts."""
    return "; ".join(f"{name}: {summary}" for name, summary in names.items())


def examples(*lines: str) -> str:
    """An `epilog` of example command lines, to end a command's --help."""
    return "examples:\n" + "\n".join(f"  {line}" for line in lines)


def writable_folder(path, option: str = "--out") -> None:
    """Create `path` if needed and check it can be written, before any work starts; the
    error names `option`, the option that chose the folder."""
    folder = pathlib.Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise CLIError(
            f"cannot write to folder '{folder}' ({error.strerror or error}); "
            f"choose another with {option}."
        ) from None
    if not os.access(folder, os.W_OK):
        raise CLIError(f"cannot write to folder '{folder}'; choose another with {option}.")
