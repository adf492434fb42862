"""`jaxcascade loop --resume / --overwrite`: a loop keeps its work in its report folder.

Every finished fit and round is written to `REPORT/checkpoints/` as it finishes
(`_loop_checkpoint`); the folder is deleted once the report is written. A run killed or
interrupted leaves it: `--resume` continues from it (the same decisions, estimates and
errors as an uninterrupted run), `--overwrite` starts afresh, and with neither the run
is refused, as a sweep refuses an existing output. Ctrl-C writes a partial report that
says where the loop stopped and how to continue, and exits with 130.
"""

from __future__ import annotations

import json
import pathlib
import shlex
import sys

from ._common import CLIError

# the checkpoint folder, inside the report folder
CHECKPOINTS = "checkpoints"
# the exit code of a run stopped by Ctrl-C (128 + SIGINT, the shell's convention)
INTERRUPTED = 130


def add_arguments(parser) -> None:
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue the loop whose checkpoints --report DIR holds (DIR/checkpoints/, "
        "left by a run that was killed or interrupted): finished fits are loaded, not "
        "refitted, and the decisions, estimates and errors are those of an uninterrupted "
        "run; refused when the records or the options that change results differ",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="delete the checkpoints in --report DIR and start afresh (without --resume or "
        "--overwrite a folder holding an earlier loop's checkpoints is refused)",
    )


def run_kept(args, run) -> int:
    """`run(args, checkpoints)`, the loop with its checkpoints in `--report`; on Ctrl-C a
    partial report and exit code 130; the checkpoints deleted once `run` returns."""
    from .._measured._loop_checkpoint import Checkpoints

    if (args.resume or args.overwrite) and not args.report:
        raise CLIError(
            f"{'--resume' if args.resume else '--overwrite'} needs --report DIR, the folder "
            "where a loop keeps its work."
        )
    folder = pathlib.Path(args.report) / CHECKPOINTS if args.report else None
    checkpoints = Checkpoints(folder, resume=args.resume, overwrite=args.overwrite)
    if args.resume and not checkpoints.held() and not args.quiet:
        print(f"--resume: '{folder}' holds no checkpoints; starting afresh", file=sys.stderr)
    try:
        code = run(args, checkpoints)
    except KeyboardInterrupt:
        return _interrupted(args, checkpoints)
    checkpoints.remove()
    return code


def resume_command(argv: list[str]) -> str:
    """The command that continues the run `jaxcascade loop ARGV`: `--resume` instead of
    `--overwrite`."""
    kept = [a for a in argv if a not in ("--overwrite", "--resume")]
    return shlex.join(["jaxcascade", "loop", *kept, "--resume"])


def _interrupted(args, checkpoints) -> int:
    where = checkpoints.describe()
    command = resume_command(sys.argv[2:])
    finished = checkpoints.finished()
    if checkpoints.folder is None:
        print(
            f"jaxcascade: interrupted {where}; nothing was kept (no --report DIR to keep "
            "the loop's work in).",
            file=sys.stderr,
        )
        return INTERRUPTED
    report = pathlib.Path(args.report)
    sentence = (
        f"The loop was interrupted {where}; {len(finished)} finished fit(s) and round(s) "
        f"are kept in '{checkpoints.folder}'."
    )
    try:
        report.mkdir(parents=True, exist_ok=True)
        from .._measured._report import interrupted_markdown

        (report / "report.md").write_text(interrupted_markdown(sentence, finished, command))
        summary = {
            "interrupted": True,
            "stopped": checkpoints.where,
            "sentence": sentence,
            "finished": finished,
            "resume": command,
        }
        (report / "report.json").write_text(json.dumps(summary, indent=1))
    except OSError:
        pass  # the checkpoints are what matters; the sentence below still says how
    print(f"jaxcascade: {sentence} Continue with: {command}", file=sys.stderr)
    return INTERRUPTED
