"""The docs run (issue 68): every Python block of `docs/` and the README is executed, the
blocks of a page in order in one namespace, from a scratch folder that sees the shared
data where the docs say it is (`../shared/data`); a function the docs name and the
package lacks fails the default run.

A block may be marked by an HTML comment on the line before it:

- `<!-- docs-test: slow (why) -->`: run only with `-m slow` (a whole loop, a sweep);
- `<!-- docs-test: fragment (why) -->`: never run (a file's content to copy, with `...`
  in it, or a block that needs a user's own objects).

Every block, run or not, is checked statically: each `jaxcascade` name it uses (`jc.NAME`,
`from jaxcascade import NAME`) must exist.
"""

import ast
import contextlib
import io
import json
import pathlib
import re

import pytest

import jaxcascade

ROOT = pathlib.Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
PAGES = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "README.md"]
BLOCK = re.compile(
    r"(?:<!--\s*docs-test:\s*(?P<mark>[a-z]+)[^>]*-->\s*\n)?(?P<indent>[ \t]*)```python\n"
    r"(?P<code>.*?)^(?P=indent)```",
    re.S | re.M,
)
SNIPPET = re.compile(r'^--8<-- "(?P<path>[^"]+)"\s*$', re.M)


def blocks(page: pathlib.Path) -> list[tuple[str, str]]:
    """`(mark, code)` of each Python block of `page` (mark "" for a block that runs in
    the default run), snippet includes (`--8<-- "path"`) read from their files."""
    out = []
    for match in BLOCK.finditer(page.read_text()):
        code = match.group("code")
        code = SNIPPET.sub(lambda m: (ROOT / m.group("path")).read_text(), code)
        indent = match.group("indent")
        if indent:
            code = "\n".join(line.removeprefix(indent) for line in code.splitlines()) + "\n"
        out.append((match.group("mark") or "", code))
    return out


def pages_with(mark: str) -> list[pathlib.Path]:
    return [p for p in PAGES if any(m == mark for m, _ in blocks(p))]


def package_names(code: str) -> set[str]:
    """The names of `jaxcascade` a block uses: `jc.NAME` / `jaxcascade.NAME` where the
    module is imported under that alias, and `from jaxcascade import NAME`."""
    tree = ast.parse(code)
    aliases = {"jaxcascade"}
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            aliases |= {a.asname or a.name for a in node.names if a.name == "jaxcascade"}
        elif isinstance(node, ast.ImportFrom) and node.module == "jaxcascade":
            names |= {a.name for a in node.names}
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id in aliases
        ):
            names.add(node.attr)
    return names


def test_every_block_is_python_and_names_only_what_the_package_has():
    checked = 0
    for page in PAGES:
        for mark, code in blocks(page):
            assert mark in ("", "slow", "fragment"), (page, mark)
            missing = {n for n in package_names(code) if not hasattr(jaxcascade, n)}
            assert not missing, f"{page.relative_to(ROOT)} names {sorted(missing)}"
            checked += 1
    assert checked >= 10  # the pages were read: README, estimation, models, tutorials ...


@pytest.fixture
def scratch(tmp_path, monkeypatch):
    """A working folder whose `../shared` is the shared data, as the docs' paths assume
    (from the repository's root), and whose `runs/` is the tests' own."""
    work = tmp_path / "work"
    (work / "runs").mkdir(parents=True)
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED, target_is_directory=True)
    monkeypatch.chdir(work)
    return work


def _run(page: pathlib.Path, marks: tuple[str, ...]) -> str:
    namespace: dict = {"__name__": f"docs:{page.stem}"}
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        for mark, code in blocks(page):
            if mark in marks:
                exec(compile(code, str(page.relative_to(ROOT)), "exec"), namespace)
    return out.getvalue()


def _needs_data(page: pathlib.Path) -> bool:
    return "../shared/" in page.read_text() and not SHARED.is_dir()


@pytest.mark.parametrize("page", pages_with(""), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_docs_python_blocks_run(page, scratch):
    if _needs_data(page):
        pytest.skip("the page reads ../shared/data, absent on this machine")
    _run(page, ("",))


@pytest.mark.slow
@pytest.mark.parametrize("page", pages_with("slow"), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_docs_slow_python_blocks_run(page, scratch):
    if _needs_data(page):
        pytest.skip("the page reads ../shared/data, absent on this machine")
    _run(page, ("", "slow"))


@pytest.mark.slow  # the loop on CED twice: about three minutes
@pytest.mark.skipif(
    not (SHARED / "data" / "nonlinear_benchmarks" / "CED").is_dir(), reason="no CED"
)
def test_the_tutorial_gets_the_command_s_ced_figures_to_the_last_digit(scratch):
    """The measured-record tutorial's Python run of CED and `jaxcascade loop --benchmark
    CED` in one sitting: every figure of the command's JSON equal."""
    from jaxcascade._cli import main
    from jaxcascade._json import strict_json

    page = ROOT / "docs" / "tutorials" / "measured_record.md"
    (code,) = [c for mark, c in blocks(page) if mark == "slow" and "loop_benchmark" in c]
    namespace: dict = {}
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compile(code, str(page), "exec"), namespace)
    python = json.loads(strict_json(namespace["run"].to_dict(brief=True)))
    out = io.StringIO()
    argv = ["loop", "--benchmark", "CED", "--data", "../shared/data/nonlinear_benchmarks"]
    with contextlib.redirect_stdout(out):
        assert main([*argv, "--json", "--quiet"]) == 0
    command = json.loads(out.getvalue())
    # the figures: the benchmark's test RMSE, every validation and test error, what the
    # loop added and the final model (the candidate list aside: a round drained for the
    # compiled programs' bound can end before its last candidates, and the second run
    # compiles fewer programs than the first)
    keys = ("benchmark", "test", "error_before", "error_after", "error_before_from_rest")
    keys += ("error_after_from_rest", "actions", "structure_after", "model_after", "verdict")
    differ = [key for key in keys if python[key] != command[key]]
    assert not differ, differ
    assert (scratch / "runs" / "ced_python" / "report.md").is_file()
