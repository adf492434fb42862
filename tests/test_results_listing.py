"""results/README.md lists every file under results/ with the committed command that
writes it, and benchmarks/run_all.sh runs every one of those commands (issue 40).

The table's "files" column: each backticked item is a path under `results/`; `{a,b}`
expands as in bash (nested, `{,x}` for nothing or `x`); `*` and a name in angle brackets
(`<run>`) match any part of one path segment; a trailing `/` covers everything under
that folder. "step" names the function of run_all.sh that runs the row's commands, and
says "needs ../shared/data" where the step reads the shared records. "command": every
backticked item starting with `python`, `jaxcascade` or `VAR=value python` is a command;
a name in angle brackets stands for the values a step loops over.

Checked here, without computing anything:
(a) every item (each brace expansion) matches at least one tracked file;
(b) every tracked file under results/ (results/README.md aside) matches an item;
(c) every row's command is in its step's function of run_all.sh: the same script or
    subcommand, the same options with the same values, the same positional arguments
    and output redirection (a `$var` of a shell loop and an `<E>` of the row match each
    other, `${VAR:-default}` reads as its default), and every command there is in a row;
    every step in run_all.sh's `all` list has a function and a row;
(d) no row says "written by hand", and every row has a command;
(e) the rows that say "needs ../shared/data" are exactly those of run_all.sh's
    `needs_shared_data` steps, and every command with `--data ../shared/...` is one.

The tracked files come from `git ls-files results`; where git or its metadata is missing
(an unpacked archive), from a walk of the folder.
"""

from __future__ import annotations

import pathlib
import re
import shlex
import subprocess

import pytest

ROOT = pathlib.Path(__file__).parents[1]
RESULTS = ROOT / "results"
README = RESULTS / "README.md"
RUN_ALL = ROOT / "benchmarks" / "run_all.sh"
SHARED = "needs ../shared/data"
WILD = "\0"  # a placeholder or a shell variable, in a command's arguments


# -- the table -----------------------------------------------------------------------


def expand_braces(pattern: str) -> list[str]:
    """Bash brace expansion, `{a,b}` in turn (nested, left to right); a brace group
    without a comma is kept as it is."""
    depth, start = 0, None
    for i, char in enumerate(pattern):
        if char == "{":
            if depth == 0:
                start = i
            depth += 1
        elif char == "}" and depth:
            depth -= 1
            if depth == 0:
                body, parts, level, last = pattern[start + 1 : i], [], 0, 0
                for j, c in enumerate(body):
                    level += (c == "{") - (c == "}")
                    if c == "," and level == 0:
                        parts.append(body[last:j])
                        last = j + 1
                if not parts:
                    continue
                parts.append(body[last:])
                head, tail = pattern[:start], pattern[i + 1 :]
                return [x for part in parts for x in expand_braces(head + part + tail)]
    return [pattern]


def pattern_regex(pattern: str) -> re.Pattern[str]:
    """A brace-free item as a regex over paths relative to results/."""
    folder = pattern.endswith("/")
    body = ""
    for token in re.split(r"(\*|<[^<>/]+>)", pattern):
        body += "[^/]+" if token.startswith("<") else "[^/]*" if token == "*" else re.escape(token)
    return re.compile(body + (".+" if folder else ""))


def cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def rows() -> list[dict]:
    """The table of results/README.md: files, step, commands and the row's text."""
    lines = README.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| files |"))
    header = cells(lines[start])
    assert {"files", "step", "command"} <= set(header), header
    table = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        row = dict(zip(header, cells(line), strict=True))
        spans = {key: re.findall(r"`([^`]+)`", value) for key, value in row.items()}
        commands = [
            c for c in spans["command"] if re.match(r"(?:\w+=\S*\s+)*(?:python|jaxcascade)\s", c)
        ]
        table.append(
            {
                "text": line,
                "files": spans["files"],
                "step": spans["step"][0] if spans["step"] else "",
                "shared": SHARED in row["step"],
                "commands": commands,
            }
        )
    return table


ROWS = rows()


def tracked() -> list[str]:
    """Files under results/ (relative to it) that the repository holds."""
    try:
        listed = subprocess.run(
            ["git", "ls-files", "-z", "results"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        files = [f.removeprefix("results/") for f in listed.split("\0") if f]
    except (OSError, subprocess.CalledProcessError):
        files = []
    if not files:  # no git, or not a checkout: what is there
        files = [p.relative_to(RESULTS).as_posix() for p in RESULTS.rglob("*") if p.is_file()]
    return sorted(f for f in files if f != "README.md")


# -- commands --------------------------------------------------------------------------


def parse_command(text: str) -> tuple[str, tuple, tuple, str | None] | None:
    """(program, positionals, options as sorted (name, value) pairs, redirect) of a
    `python benchmarks/X.py` or `jaxcascade SUB` command; None for anything else (rm, a
    loop's keywords)."""
    text = re.sub(r"\$\{\w+:-([^}]*)\}", r"\1", text)  # ${VAR:-default}: the default
    text = re.sub(r"\$\{?\w+\}?|<[^<>\s]+>", WILD, text)
    try:
        tokens = shlex.split(text)
    except ValueError:
        return None
    while tokens and re.fullmatch(r"\w+=\S*", tokens[0]):
        tokens = tokens[1:]  # PYTHONPATH=.
    if len(tokens) >= 2 and tokens[0] == "python" and tokens[1].startswith("benchmarks/"):
        program, rest = tokens[1], tokens[2:]
    elif len(tokens) >= 2 and tokens[0] == "jaxcascade":
        program, rest = f"jaxcascade {tokens[1]}", tokens[2:]
    else:
        return None
    positionals, options, redirect, i = [], {}, None, 0
    while i < len(rest):
        token = rest[i]
        if token.startswith(">"):
            target = token[1:] or (rest[i + 1] if i + 1 < len(rest) else "")
            i += 1 if token[1:] else 2
            redirect = None if target == "/dev/null" else target
            continue
        if token.startswith("--"):
            name, _, value = token.partition("=")
            if not value and i + 1 < len(rest) and not rest[i + 1].startswith(("--", ">")):
                value, i = rest[i + 1], i + 1
            options[name] = value or True
        else:
            positionals.append(token)
        i += 1
    return program, tuple(positionals), tuple(sorted(options.items())), redirect


def show(command) -> str:
    program, positionals, options, redirect = command
    words = [program, *positionals]
    words += [k if v is True else f"{k} {v}" for k, v in options]
    words += [f"> {redirect}"] if redirect else []
    return " ".join(words).replace(WILD, "<*>")


def steps() -> dict[str, list]:
    """run_all.sh's step functions: name -> the commands in it (continuations joined,
    comments dropped)."""
    text = RUN_ALL.read_text().replace("\\\n", " ")
    found = {}
    for match in re.finditer(r"^(\w+)\(\) \{(.*?)^\}", text, re.M | re.S):
        commands = []
        for line in match.group(2).splitlines():
            line = re.sub(r"(^|\s)#.*", "", line)
            for part in re.split(r";|&&|\|\|", line):
                parsed = parse_command(part.strip())
                if parsed:
                    commands.append(parsed)
        found[match.group(1)] = commands
    return found


def bash_list(name: str) -> list[str]:
    match = re.search(rf"^{name}=\(([^)]*)\)", RUN_ALL.read_text(), re.M)
    assert match, f"benchmarks/run_all.sh has no `{name}=(...)` list"
    return match.group(1).split()


STEPS = steps()


# -- the checks -----------------------------------------------------------------------


def test_the_pattern_rules():
    assert expand_braces("a{1,2}_{x,{y,z}}{,_r}.md") == [
        f"a{n}_{s}{r}.md" for n in "12" for s in "xyz" for r in ("", "_r")
    ]
    assert expand_braces("a{b}c") == ["a{b}c"]
    assert pattern_regex("brfd/<run>/").fullmatch("brfd/x+y_z/fig/a.png")
    assert not pattern_regex("brfd/<run>/").fullmatch("brfd/table.md")
    assert pattern_regex("sweep_example2_paper.*").fullmatch("sweep_example2_paper.summary.csv")
    assert not pattern_regex("bench.csv").fullmatch("bench_csv")
    sweep = parse_command("jaxcascade sweep --example $ex --out r/s$ex.parquet --json > o.json")
    assert sweep == parse_command(
        "jaxcascade sweep --json --out r/s<E>.parquet --example <E> >o.json"
    )
    shared = parse_command('PYTHONPATH=. python benchmarks/b.py "${D:-../shared/x}" --q')
    assert shared == ("benchmarks/b.py", ("../shared/x",), (("--q", True),), None)


def test_the_table_has_rows_and_run_all_has_steps():
    assert len(ROWS) > 10, "results/README.md: no `| files | ... |` table found"
    assert len(STEPS) > 10, "benchmarks/run_all.sh: no step functions found"


def test_every_listed_file_exists():
    files = tracked()
    missing = [
        f"{item} (as {expanded})"
        for row in ROWS
        for item in row["files"]
        for expanded in expand_braces(item)
        if not any(pattern_regex(expanded).fullmatch(f) for f in files)
    ]
    assert not missing, (
        "results/README.md lists files that are not under results/ (git ls-files):\n  "
        + "\n  ".join(missing)
    )


def test_every_file_is_listed():
    regexes = [
        pattern_regex(x) for row in ROWS for item in row["files"] for x in expand_braces(item)
    ]
    unlisted = [f for f in tracked() if not any(r.fullmatch(f) for r in regexes)]
    assert not unlisted, (
        f"{len(unlisted)} files under results/ match no row of results/README.md's table "
        "(add a row with the command that writes them):\n  " + "\n  ".join(unlisted)
    )


def test_no_row_is_written_by_hand_and_every_row_has_a_command():
    by_hand = [r["text"][:120] for r in ROWS if re.search(r"by hand", r["text"], re.I)]
    assert not by_hand, "rows of results/README.md written by hand:\n  " + "\n  ".join(by_hand)
    bare = [", ".join(r["files"]) for r in ROWS if not r["commands"]]
    assert not bare, (
        "rows of results/README.md with no `python ...` or `jaxcascade ...` command:\n  "
        + "\n  ".join(bare)
    )


def test_every_command_of_the_table_is_in_its_step_of_run_all():
    problems = []
    for row in ROWS:
        name = ", ".join(row["files"])
        if row["step"] not in STEPS:
            problems.append(f"{name}: step {row['step']!r} is no function of run_all.sh")
            continue
        for text in row["commands"]:
            command = parse_command(text)
            if command not in STEPS[row["step"]]:
                near = [show(c) for c in STEPS[row["step"]] if c[0] == command[0]]
                problems.append(
                    f"{name}: `{show(command)}` is not in step {row['step']}"
                    + (" (there: " + "; ".join(near) + ")" if near else "")
                )
    assert not problems, "results/README.md and benchmarks/run_all.sh disagree:\n  " + (
        "\n  ".join(problems)
    )


def test_every_command_of_run_all_is_in_a_row_and_every_step_runs():
    listed = {(row["step"], parse_command(text)) for row in ROWS for text in row["commands"]}
    extra = [
        f"{step}: {show(command)}"
        for step, commands in STEPS.items()
        for command in commands
        if (step, command) not in listed
    ]
    assert not extra, (
        "commands of benchmarks/run_all.sh that no row of results/README.md lists "
        "(under that step):\n  " + "\n  ".join(extra)
    )
    run = bash_list("all")
    undefined = [s for s in run if s not in STEPS]
    assert not undefined, f"run_all.sh's `all` names steps it does not define: {undefined}"
    unused = sorted({r["step"] for r in ROWS} - set(run))
    assert not unused, f"steps of results/README.md that run_all.sh's `all` leaves out: {unused}"
    idle = [s for s in run if not STEPS[s]]
    assert not idle, f"steps of run_all.sh that run no command of the table: {idle}"


def test_the_rows_that_need_shared_data_say_so():
    needs = set(bash_list("needs_shared_data"))
    assert needs <= set(STEPS), f"needs_shared_data names unknown steps: {needs - set(STEPS)}"
    wrong = []
    for row in ROWS:
        reads = any("../shared/" in text for text in row["commands"])
        if row["shared"] != (row["step"] in needs):
            wrong.append(
                f"{', '.join(row['files'])}: step {row['step']} is "
                f"{'' if row['step'] in needs else 'not '}in needs_shared_data, the row "
                f"{'says' if row['shared'] else 'does not say'} {SHARED!r}"
            )
        if reads and not row["shared"]:
            wrong.append(f"{', '.join(row['files'])}: reads ../shared/ but does not say so")
    assert not wrong, "\n  ".join(["shared data marked inconsistently:", *wrong])


@pytest.mark.parametrize("step", sorted(set(bash_list("needs_shared_data"))))
def test_a_step_that_reads_shared_data_reads_it(step):
    assert any(
        "../shared/" in " ".join(c[1]) + " ".join(str(v) for _, v in c[2])
        for c in STEPS.get(step, [])
    ), f"run_all.sh step {step} is in needs_shared_data but reads no ../shared/ path"
