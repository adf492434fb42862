"""The README's first command can run again and again in a clone: it writes under the
git-ignored `runs/` and replaces its own earlier output (`--overwrite`); the command
itself is exercised at small size by test_montecarlo.py's overwrite test."""

import pathlib
import shlex

from jaxcascade._cli import build_parser

ROOT = pathlib.Path(__file__).parents[1]


def first_command() -> list[str]:
    text = (ROOT / "README.md").read_text()
    block = text.split("```bash\n", 1)[1].split("```", 1)[0]
    line = block.strip().split("&&")[-1]
    words = shlex.split(line)
    assert words[0] == "jaxcascade"
    return words[1:]


def test_quickstart_writes_under_the_ignored_scratch_folder_and_overwrites():
    args = build_parser().parse_args(first_command())
    assert args.overwrite and not args.resume
    assert pathlib.PurePath(args.out).parts[0] == "runs"
    assert pathlib.PurePath(args.plots).parts[0] == "runs"
    ignored = (ROOT / ".gitignore").read_text().split()
    assert "runs/" in ignored
