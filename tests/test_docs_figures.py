"""README.md and the docs retype no result (issue 40): a measured or computed figure (a
time, a rate, a ratio, an error, a success rate, a count of tests) is quoted by including
its file from `results/` (`--8<--`, pymdownx.snippets) or by naming the file, never by
typing the number into the page, where it would drift from the file.

The detector reads each page as prose: fenced code blocks, inline code spans, snippet
include lines, link targets, URLs, HTML comments and commit hashes are blanked first
(line and column kept). What is left is matched against RULES; a hit whose figure lies
inside a match of ALLOWED (a parameter, a threshold or a version, not a result) is let
through. A failure names the page, the line, the rule and the text.
"""

import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])

_NUMBER = r"\d[\d,]*(?:\.\d+)?"
_UNITS = (
    r"(?:s|ms|us|µs|ns|sec|secs|seconds?|min|mins|minutes?|hours?|%|x|×"
    r"|[kMGT]i?B|[kMGT]?[Ff]lops?(?:/s)?)"
)

# Each rule: what a retyped result looks like. The group `num` is the figure itself.
RULES: dict[str, re.Pattern[str]] = {
    # 22 min, 16.3 s, 5-9 ms, 1.20x, 31 %, 2.0 GB, 193 GFlop/s
    "a figure with a unit": re.compile(rf"(?<![\w.])(?P<num>{_NUMBER})\s*{_UNITS}(?![\w/])"),
    # 4240 fits/s, 914 per s, 48.9 fits per second
    "a rate": re.compile(
        rf"(?<![\w.])(?P<num>{_NUMBER})\s*(?:fits|realisations|records|updates|samples)?"
        r"\s*(?:/\s*s\b|per\s+s(?:ec(?:ond)?)?\b)"
    ),
    # 0.97, 0.344, 2.2e-9, 1e-15: a ratio, an error, an efficiency, a tolerance reached
    "a decimal": re.compile(r"(?<![\w.])(?P<num>\d+\.\d+(?:e[-+]?\d+)?|\d+e[-+]?\d+)(?!\w|\.\d)"),
    # 39/40, 187 of 200, 6 of 6: a success count
    "a count of successes": re.compile(rf"(?<![\w./])(?P<num>{_NUMBER})\s*(?:of|/)\s*\d"),
    # 616 tests, 615 passed, one failed
    "a count of tests": re.compile(
        rf"(?<![\w.])(?P<num>{_NUMBER})\s+(?:tests|passed|failed|errors|skipped)\b"
    ),
    # 862 -> 555, 245 -> 248: a before and after
    "a change": re.compile(rf"(?<![\w.])(?P<num>{_NUMBER})\s*(?:->|→)\s*\d"),
    # 84 times the baseline
    "a multiple": re.compile(rf"(?<![\w.])(?P<num>{_NUMBER})\s+times\b"),
    # about 15, median re-entry 525, in 21 iterations, load 0.9, NRMSE 0.39
    "a figure in a results phrase": re.compile(
        r"\b(?:about|around|roughly|approximately|nearly|almost|median|mean)\s+"
        rf"(?:[A-Za-z'-]+\s+){{0,4}}?(?P<num>{_NUMBER})"
        rf"|\bin\s+(?P<iter>\d+)\s+iterations\b"
        rf"|\b(?:load|NRMSE|RMSE|efficiency|recovered|converged)\s+(?P<val>{_NUMBER})"
    ),
}

# What is not a result, though it is a number: each entry a regex and why.
ALLOWED: list[tuple[str, str]] = [
    (r"Python \d+\.\d+\+?", "the supported Python version"),
    (r"arXiv \d+\.\d+", "a paper's arXiv identifier"),
    (
        r"\b(?!(?:NRMSE|RMSE|efficiency|bias|std|error)\b)[A-Za-z_]\w*\s*=\s*-?\d[\d.]*",
        "a setting or an initial value written as name = value (mR = 0.5, lam = 0.95)",
    ),
    (r"\(default \d+(?:\.\d+)?", "a setting's default"),
    (r"\bat most \d+(?:\.\d+)?", "a bound the method imposes (at most 2.5, 3 times the level)"),
    (r"\d+e-\d+ relative", "a stopping rule's relative tolerance"),
    (r"(?:within|than) 0\.05\b", "the recovery tolerance: every parameter within 0.05"),
    (r"\bpoles? \d\.\d+", "the pole of a simulated noise, a setting of the experiment"),
    (r"\d+ % lower NRMSE", "the loop's minimum gain (--min-gain)"),
    (r"least 2 % of (?:the residual|it)", "the threshold of `_feedback.MIN_EXPLAINED`"),
    (r"relative 1e-9", "the tolerance a test states for tables compared across backends"),
    (r"mean \(NRMSE 1\)", "the mean's NRMSE, 1 by definition"),
    (r"(?:within|than|or) 1 %", "the sample-period tolerance and a refit's margin"),
    (r"fewer than 5 %", "scaling auto's test of a one-sided input"),
    (r"within 1e-3 of the unit circle", "the test of an integrating output"),
    (r"below 1e100", "the record check's bound on a value's magnitude"),
    (r"1-50 % of the input span", "the Prandtl-Ishlinskii operator's threshold grid"),
    (r"\d+-\d+ % and \d+-\d+ % bands", "the quantile bands a figure draws"),
    (r"99 % band", "the confidence level of the band a residual figure draws"),
    (r"1\.4826 times", "the normal consistency factor of the median absolute deviation"),
    (r"quantile of 0\.01\b", "the outlier rule's level (`_measured._outliers.ALPHA`)"),
    (
        r"neighbours by up to 12 robust scales, but by at most 0\.27",
        "CED's largest departure (robust scales; output std), why `_outliers` has floors",
    ),
    (
        r"99\.9 % of the power [\s\S]{0,80}? below 0\.4/d",
        "the benchmarks' decimation rule (`_measured._benchmark_protocol.BENCHMARK_DECIMATION`)",
    ),
]
# A space in an entry matches any run of whitespace, a line break too.
_ALLOWED = [re.compile(pattern.replace(" ", r"\s+")) for pattern, _ in ALLOWED]


def _false_additions(match: re.Match[str]) -> list[tuple[str, str]]:
    """(in the page, in the file) for the false-addition counts of the README."""
    import pandas as pd

    table = pd.read_csv(ROOT / "results" / "false_additions.csv")
    pairs = []
    for n, group in table.groupby("n"):
        k, count = int(group["false_addition"].sum()), len(group)
        pairs.append((match.group(f"n{n}"), f"{k} of {count}"))
    return pairs


def _outliers(match: re.Match[str]) -> list[tuple[str, str]]:
    """(in the page, in the file) for the README's outlier figures."""
    import pandas as pd

    table = pd.read_csv(ROOT / "results" / "outliers.csv")
    clean = table[table["record"] == "clean"]
    named = clean[["named_estimation", "named_validation"]].notna().any(axis=1)
    spiked = table[table["record"] == "spiked"]
    auto = spiked[spiked["outliers_option"] == "auto"]
    keep = spiked[spiked["outliers_option"] == "keep"]
    found = int((auto["named_estimation"] == "150,300,451,820").sum())
    shift, kept = auto["largest_shift_in_std_errors"], keep["largest_shift_in_std_errors"]
    return [
        (match.group("alarms"), f"{int(named.sum())} of {len(clean)}"),
        (match.group("found"), f"{found} of {len(auto)}"),
        (match.group("shift"), f"{shift.max():.2f}"),
        (match.group("kept"), f"{kept.min():.1f} to {kept.max():.1f}"),
    ]


# Figures a page may quote because a test reads them back from their results file: the
# page, the phrase (named groups hold the figures) and what the file says.
VERIFIED = [
    (
        "README.md",
        r"false additions: (?P<n1024>\d+ of \d+) records at N = 1024 and "
        r"(?P<n2000>\d+ of \d+) at N = 2000",
        _false_additions,
    ),
    (
        "README.md",
        r"named outliers on (?P<alarms>\d+ of \d+) records; on ten of them with four spikes of "
        r"5 to 6 output standard deviations it named all four on (?P<found>\d+ of \d+), and "
        r"no estimate moved by more than (?P<shift>[\d.]+) of the clean fit's standard errors "
        r"\(with the spikes kept: (?P<kept>[\d.]+ to [\d.]+)\)",
        _outliers,
    ),
]

_FENCE = re.compile(r"^\s*(`{3,}|~{3,})")
_SNIPPET = re.compile(r"^\s*-+8<-+(?:\s|$)")
_BLANKED = [
    re.compile(r"<!--.*?-->", re.S),  # HTML comments
    re.compile(r"(`+)(?:(?!\n[ \t]*\n).)+?\1", re.S),  # inline code, within a paragraph
    re.compile(r"\]\([^)\s]*\)"),  # link targets
    re.compile(r"^\s*\[[^\]]+\]:\s*\S+.*$", re.M),  # link reference definitions
    re.compile(r"<?https?://[^\s>)]+>?"),  # URLs and autolinks
    re.compile(r"\b(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b"),  # commit hashes
]


def _blank(match: re.Match[str]) -> str:
    return re.sub(r"[^\n]", " ", match.group(0))


def prose(text: str) -> str:
    """The page with everything but prose blanked, so positions and lines are kept."""
    lines = text.split("\n")
    fence = None
    for i, line in enumerate(lines):
        opening = _FENCE.match(line)
        if fence is None and opening:
            fence = opening.group(1)
            lines[i] = ""
        elif fence is not None:
            if opening and opening.group(1)[0] == fence[0] and len(opening.group(1)) >= len(fence):
                fence = None
            lines[i] = ""
        elif _SNIPPET.match(line):  # a snippet include: the figure comes from the file
            lines[i] = ""
    text = "\n".join(lines)
    for pattern in _BLANKED:
        text = pattern.sub(_blank, text)
    return text


def retyped(text: str) -> list[tuple[int, str, str]]:
    """(line, rule, figure) for every retyped result in a page's text."""
    body = prose(text)
    allowed = [m.span() for pattern in _ALLOWED for m in pattern.finditer(body)]
    # a verified phrase is checked against its file by test_verified_figures_match_their_files
    allowed += [
        m.span()
        for _, phrase, _ in VERIFIED
        for m in re.finditer(phrase.replace(" ", r"\s+"), body)
    ]
    found = {}
    for rule, pattern in RULES.items():
        for match in pattern.finditer(body):
            group = next(g for g in ("num", "iter", "val") if match.groupdict().get(g))
            start, end = match.span(group)
            if any(a <= start and end <= b for a, b in allowed):
                continue
            line = body.count("\n", 0, start) + 1
            found.setdefault((line, start), (line, rule, match.group(0).strip()))
    return sorted(found.values())


def test_the_detector_finds_retyped_figures_and_lets_parameters_through():
    page = (
        "It takes about 20 s, 616 tests in 22 min 14 s.\n"
        "Robust reaches 4240 fits/s, 84 times the baseline, and efficiency 0.97;\n"
        "recovered 187 of 200 (93%), NRMSE 862 -> 555.\n"
        "Python 3.11+, arXiv 2405.10779, commit 3ea3a34, `0.97 s`, [x](a1.5x.md).\n"
        "Initial values mR = 0.5, every parameter within 0.05, AR(1) noise with pole 0.9,\n"
        "a sample period within 1 %, the mean (NRMSE 1), issue 40, orders 2,2,2,2.\n"
        "```text\n10.2 s\n```\n"
        '    --8<-- "results/bench.csv"\n'
    )
    hits = retyped(page)
    figures = " ".join(figure for _, _, figure in hits)
    for figure in ("20 s", "616 tests", "22 min", "14 s", "4240 fits/s", "84 times", "0.97"):
        assert figure in figures, (figure, hits)
    for figure in ("187 of 2", "93%", "862 ->"):
        assert figure in figures, (figure, hits)
    assert {line for line, _, _ in hits} == {1, 2, 3}, hits


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_page_retypes_a_result(page):
    lines = page.read_text().split("\n")
    hits = retyped("\n".join(lines))
    message = "\n".join(
        f"{page.relative_to(ROOT)}:{line}: {rule} {figure!r}: {lines[line - 1].strip()}"
        for line, rule, figure in hits
    )
    assert not hits, (
        "a result is retyped; include its file from results/ (--8<--) or name the file "
        "instead of the number, or add a non-result to ALLOWED with its reason:\n" + message
    )


@pytest.mark.parametrize(
    ("page", "phrase", "expected"), VERIFIED, ids=[f"{v[0]}:{v[2].__name__}" for v in VERIFIED]
)
def test_verified_figures_match_their_files(page, phrase, expected):
    body = prose((ROOT / page).read_text())
    matches = list(re.finditer(phrase.replace(" ", r"\s+"), body))
    assert len(matches) == 1, f"{page}: the phrase {phrase!r} is not there once"
    for quoted, held in expected(matches[0]):
        assert quoted == held, f"{page} says {quoted!r}, the results file {held!r}"
