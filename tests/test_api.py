"""The public API the docs list (docs/api.md) is what `import jaxcascade` exports."""

import pathlib
import re
import types

import jaxcascade

API_PAGE = pathlib.Path(__file__).parents[1] / "docs" / "api.md"


def documented_api() -> set[str]:
    text = API_PAGE.read_text()
    section = text.split("\n## Public API\n", 1)[1].split("\n## ", 1)[0]
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


def test_docs_list_the_exports():
    assert documented_api() == exported()


def test_docstring_names_every_export():
    doc = jaxcascade.__doc__
    missing = {name for name in exported() if f"`{name}`" not in doc}
    assert not missing
