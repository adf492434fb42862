"""Every benchmark script's imports of the package name modules and names that exist.

The scripts of `benchmarks/` run in `run_all.sh`, not in the test run: a module moved or a
function renamed would show only there, days later (`run_all.sh`'s `profile` step failed
for two days after issue 34's layout moved modules, in the half that profiles an old
commit, which this test cannot see). Read with `ast` (module level, inside functions and
in code kept in a string for another process) and checked by importing the modules of
today's package, without running the scripts.
"""

import ast
import importlib
import pathlib
import re

import pytest

BENCHMARKS = pathlib.Path(__file__).parents[1] / "benchmarks"


def package_imports(path: pathlib.Path):
    """`(line, module, name)` of each `from jaxcascade... import name` and `(line, module,
    None)` of each `import jaxcascade...` in the script at `path`, also in the code a
    script keeps in a string to run in another process."""
    yield from _imports(ast.parse(path.read_text()), 0)


def _imports(tree, offset: int):
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            if "import" in node.value and "jaxcascade" in node.value:
                try:
                    code = ast.parse(node.value)
                except SyntaxError:  # text, not code
                    continue
                yield from _imports(code, offset + node.lineno - 1)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            if node.module.split(".")[0] == "jaxcascade":
                for alias in node.names:
                    yield offset + node.lineno, node.module, alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "jaxcascade":
                    yield offset + node.lineno, alias.name, None


def missing(path: pathlib.Path) -> list[str]:
    found = []
    for line, module, name in package_imports(path):
        try:
            imported = importlib.import_module(module)
        except ModuleNotFoundError:
            found.append(f"line {line}: no module {module}")
            continue
        if name is None or name == "*" or hasattr(imported, name):
            continue
        try:
            importlib.import_module(f"{module}.{name}")  # a submodule
        except ModuleNotFoundError:
            found.append(f"line {line}: {module} has no {name}")
    return found


SCRIPTS = sorted(BENCHMARKS.glob("*.py"))


def test_every_import_statement_of_the_package_is_read():
    # the statements the `ast` walk finds are the lines that a plain text search finds
    pattern = re.compile(r"^\s*[\"']?(from|import) jaxcascade\b", re.MULTILINE)
    for path in SCRIPTS:
        found = {line for line, _, _ in package_imports(path)}
        assert len(found) == len(pattern.findall(path.read_text())), path.name
    assert sum(bool(pattern.search(p.read_text())) for p in SCRIPTS) > len(SCRIPTS) // 2


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: p.name)
def test_a_scripts_imports_of_the_package_exist(path):
    assert missing(path) == []


def test_a_moved_module_is_found(tmp_path):
    script = tmp_path / "old.py"
    script.write_text(
        "from jaxcascade._normal_equations import solve_step\n"
        "def main():\n"
        "    from jaxcascade._system._model import Orders, no_such_name\n"
    )
    assert missing(script) == [
        "line 1: no module jaxcascade._normal_equations",
        "line 3: jaxcascade._system._model has no no_such_name",
    ]
