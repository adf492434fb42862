"""The package's layers (docs/architecture.md): each module imports only layers below its
own, nothing imports in a circle, and the command line sits on top, alone with argparse.
Read from the source with `ast`, every import counted (module level and inside
functions)."""

import ast
import pathlib

PACKAGE = pathlib.Path(__file__).parents[1] / "jaxcascade"

# Lowest first, as in docs/architecture.md; a package (folder) is one room.
LAYERS = [
    {
        "_status",
        "_metrics",
        "_version",
        "_linalg",
        "_compile",
        "_native",
        "_names",
        "_defaults",
        "_json",
    },
    {"_system"},
    {"_data"},
    {"_experiment"},
    {"_estimator"},
    {"_measured"},
    {"_montecarlo"},
    {"_plot", "_benchmark"},
    {"_workflow"},
    {"_cli"},
    {"__init__", "__main__"},
]


def room(path: pathlib.Path) -> str:
    relative = path.relative_to(PACKAGE)
    return relative.parts[0] if len(relative.parts) > 1 else relative.stem


def imports(path: pathlib.Path) -> set[str]:
    """The package's rooms that the module at `path` imports (itself excluded)."""
    tree = ast.parse(path.read_text())
    package = path.relative_to(PACKAGE.parent).with_suffix("").parts[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the module's package
                base = package[: len(package) - node.level + 1]
                target = (*base, *(node.module.split(".") if node.module else ()))
                names = [target] if node.module else [(*base, a.name) for a in node.names]
            else:
                names = [tuple(node.module.split("."))] if node.module else []
        elif isinstance(node, ast.Import):
            names = [tuple(a.name.split(".")) for a in node.names]
        else:
            continue
        for parts in names:
            if parts[0] == "jaxcascade" and len(parts) > 1:
                found.add(parts[1])
    return found - {room(path)}


def modules():
    return sorted(PACKAGE.rglob("*.py"))


def test_every_module_has_a_layer():
    rooms = {room(p) for p in modules()}
    assert rooms <= set().union(*LAYERS), rooms - set().union(*LAYERS)


def test_no_import_goes_up_or_sideways_into_a_circle():
    level = {name: i for i, layer in enumerate(LAYERS) for name in layer}
    upward = [
        (str(p.relative_to(PACKAGE)), target)
        for p in modules()
        for target in imports(p)
        if target in level and level[target] > level[room(p)]
    ]
    assert not upward
    graph: dict[str, set[str]] = {}
    for p in modules():
        graph.setdefault(room(p), set()).update(t for t in imports(p) if t in level)
    seen, active = set(), set()

    def visit(node, trail):
        assert node not in active, f"import circle: {' -> '.join([*trail, node])}"
        if node in seen:
            return
        active.add(node)
        for nxt in sorted(graph.get(node, ())):
            visit(nxt, [*trail, node])
        active.discard(node)
        seen.add(node)

    for node in sorted(graph):
        visit(node, [])


def test_only_the_command_line_parses_arguments():
    for p in modules():
        if room(p) in ("_cli", "__main__"):
            continue
        text = p.read_text()
        assert "argparse" not in text, p
        assert "_cli" not in imports(p), p


# What a function of the command line may not do (issue 68): split records, decimate,
# score, or write a report's text. Names of such functions, and the Markdown a report's
# text is made of.
DOMAIN_WORDS = ("split", "decimat", "score", "nrmse", "markdown", "summary", "verdict")
DOMAIN_WORDS += ("equation", "coverage", "integrat", "arx", "band_edge", "report_text")
MARKDOWN = ("|---", "\n## ", "# Model-error loop report")
# the commands that import neither NumPy nor pandas nor SciPy: they parse, call a function
# of `_workflow` (the measured-data side, `reproduce`) or `_benchmark` (`bench`) and print
# what it returns
MEASURED_COMMANDS = ("_fit.py", "_loop.py", "_loop_options.py", "_loop_resume.py", "_simulate.py")
MEASURED_COMMANDS += ("_reproduce.py", "_bench.py")


def cli_functions():
    """`(module, function name, its string constants)` of every function `_cli/` defines."""
    for path in sorted((PACKAGE / "_cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                strings = [
                    n.value
                    for n in ast.walk(node)
                    if isinstance(n, ast.Constant) and isinstance(n.value, str)
                ]
                yield path.name, node.name, strings


def test_the_command_line_holds_no_domain_rule():
    listed = list(cli_functions())
    assert len(listed) > 40  # every module's functions were read
    named = [
        (module, name)
        for module, name, _ in listed
        if any(word in name.lower() for word in DOMAIN_WORDS)
    ]
    assert not named
    writing = [
        (module, name)
        for module, name, strings in listed
        if module in MEASURED_COMMANDS and any(m in s for s in strings for m in MARKDOWN)
    ]
    assert not writing
    for module in MEASURED_COMMANDS:
        heavy = {"numpy", "pandas", "scipy"} & {
            (node.module or "").split(".")[0] if isinstance(node, ast.ImportFrom) else a.name
            for node in ast.walk(ast.parse((PACKAGE / "_cli" / module).read_text()))
            if isinstance(node, ast.Import | ast.ImportFrom)
            for a in node.names
        }
        assert not heavy, (module, heavy)


def test_the_loop_command_is_short():
    # issue 68: 1,241 lines before; the loop's rules now live in _measured/ and _workflow/
    assert len((PACKAGE / "_cli" / "_loop.py").read_text().splitlines()) < 300
