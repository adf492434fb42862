"""The public API the README lists is what `import jaxcascade` exports."""

import pathlib
import re
import types

import jaxcascade

README = pathlib.Path(__file__).parents[1] / "README.md"


def readme_api() -> set[str]:
    text = README.read_text()
    section = text.split("### Public API", 1)[1].split("\n## ", 1)[0]
    body = section.split("\n- ", 1)[1]  # the bullet list, after the introduction
    return set(re.findall(r"`([A-Za-z_][A-Za-z0-9_]*)`", body))


def exported() -> set[str]:
    # the names are imported on first use: `dir` lists them, `getattr` imports them
    return {
        name
        for name in dir(jaxcascade)
        if not name.startswith("_") and not isinstance(getattr(jaxcascade, name), types.ModuleType)
    }


def test_all_lists_every_export():
    # `exported` resolves every name `dir` lists (an unresolvable one raises)
    assert set(jaxcascade.__all__) == exported()


def test_readme_lists_the_exports():
    assert readme_api() == exported()


def test_docstring_names_every_export():
    doc = jaxcascade.__doc__
    missing = {name for name in exported() if f"`{name}`" not in doc}
    assert not missing
