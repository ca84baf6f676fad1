"""The manual stays true and apart from the lab notebook: reference.md's parameter tables
are the schema's (scripts/gen_reference.py), architecture.md names every module, the
manual pages hold no dated measurements (those live in docs/studies/ and results.md), and
the README's Python block runs as written."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
from commands import script

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
# the manual: what is true now; docs/studies/ and results.md are the dated notebook
MANUAL = [README, *sorted(path for path in DOCS.glob("*.md") if path.name != "results.md")]

DATE = re.compile(r"\b(?:19|20)\d\d-[01]\d-[0-3]\d\b")
# a commit: 7-40 hex digits (a digit and a letter among them) in backticks, or after
# "commit" or "at"
COMMIT = re.compile(r"`(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}`"
                    r"|\b(?:commits?|at) `?(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b")
BEFORE_AFTER = re.compile(r"\bbefore\s*(?:/|->|→|and|vs\.?)\s*after\b", re.I)


STUDY_LINK = re.compile(r"\]\((?:docs/)?studies/[^)]*\)")  # a study's name holds its date


def dated(line: str) -> str | None:
    """What makes a line of the manual a dated measurement, or None."""
    line = STUDY_LINK.sub("]()", line)
    if DATE.search(line):
        return "a date"
    if COMMIT.search(line):
        return "a commit hash"
    if line.lstrip().startswith("|") and BEFORE_AFTER.search(line):
        return "a before/after table"
    return None


@pytest.mark.parametrize("line, found", [
    ("Measured 2026-12-01 on this machine", "a date"),
    ("## Earlier results (commit 4fa76e2)", "a commit hash"),
    ("the rows again at bcf4816 (51 s wall)", "a commit hash"),
    ("as `20e34d0` left it", "a commit hash"),
    ("| metro, 1: before / after | 40 / 50 |", "a before/after table"),
    ("| threshold | one-step RMS before -> after |", "a before/after table"),
    ("a frozen node is named after 5 s, before the others stop", None),
    ("`profile.ato.start_speed` (0.1 m/s) with 1234567 steps", None),
    ("[the study](studies/journey-delay-2026-12-03.md)", None),
])
def test_dated_content_is_recognised(line, found):
    assert dated(line) == found


def test_the_manual_pages_hold_no_dates_commits_or_before_after_tables():
    found = [f"{path.relative_to(ROOT)}:{number}: {dated(line)}" for path in MANUAL
             for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if dated(line)]
    assert not found, "dated content belongs in docs/studies/ or results.md: " + "; ".join(found)


def test_the_reference_parameter_tables_are_the_schemas(tmp_path):
    current = script("gen_reference.py", "--check")
    assert current.returncode == 0, current.stderr
    stale = tmp_path / "reference.md"
    stale.write_text((DOCS / "reference.md").read_text(encoding="utf-8")
                     .replace("| `run.period` | `0.05` |", "| `run.period` | `0.1` |"),
                     encoding="utf-8")
    result = script("gen_reference.py", "--check", "--reference", stale)
    assert result.returncode == 1 and "stale" in result.stderr
    assert script("gen_reference.py", "--write", "--reference", stale).returncode == 0
    assert stale.read_text(encoding="utf-8") == (DOCS / "reference.md").read_text(encoding="utf-8")


def module_names(path: Path) -> tuple[str, ...]:
    """The ways architecture.md may name a module: its path from the checkout or from the
    package, `name.py` or `name`; a package's __init__.py by its folder."""
    relative = path.relative_to(ROOT)
    if path.name == "__init__.py":
        folder = path.parent.name
        return (f"{relative.parent}/", f"`{folder}/`", f"`{folder}`", f"{folder}/")
    inner = "/".join(relative.parts[1:])
    return (str(relative), inner, f"`{path.name}`", f"`{path.stem}`", f"{path.name}")


def test_architecture_names_every_module():
    text = (DOCS / "architecture.md").read_text(encoding="utf-8")
    modules = sorted([*(ROOT / "ato_nodes").rglob("*.py"), *(ROOT / "scripts").glob("*.py")])
    missing = [str(path.relative_to(ROOT)) for path in modules
               if not any(name in text for name in module_names(path))]
    assert not missing, "docs/architecture.md does not name " + ", ".join(missing)


def test_the_readme_is_short_and_lists_every_manual_page():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 300
    docs_list = text[text.index("## Documentation"):]
    pages = [path for path in MANUAL if path != README] + [DOCS / "results.md"]
    missing = [path.name for path in pages if f"(docs/{path.name}" not in docs_list]
    assert not missing and "(docs/studies/" in docs_list, missing


def test_the_readme_python_block_runs_as_written(tmp_path):
    """The in-process API as the README shows it, run outside the checkout."""
    blocks = re.findall(r"^```python\n(.*?)^```$", README.read_text(encoding="utf-8"),
                        re.M | re.S)
    assert len(blocks) == 1
    result = subprocess.run([sys.executable, "-c", blocks[0]], capture_output=True, text=True,
                            timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "stopping error" in result.stdout


def anchors(page: Path) -> set[str]:
    """The anchors GitHub gives a page's headings (lower case, punctuation dropped, spaces
    as hyphens, a repeated heading numbered)."""
    found, seen = set(), {}
    for line in page.read_text(encoding="utf-8").splitlines():
        heading = re.match(r"#+ (.*)", line)
        if heading:
            anchor = re.sub(r"[^\w\- ]", "", heading[1].strip().lower()).replace(" ", "-")
            found.add(f"{anchor}-{seen[anchor]}" if anchor in seen else anchor)
            seen[anchor] = seen.get(anchor, 0) + 1
    return found


def test_every_link_of_the_manual_and_the_notebook_resolves():
    broken = []
    for page in [README, *sorted(DOCS.rglob("*.md"))]:
        text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if target.startswith(("http:", "https:", "mailto:")):
                continue
            path, _, anchor = target.partition("#")
            linked = (page.parent / path).resolve() if path else page
            if not linked.exists() or (anchor and linked.suffix == ".md"
                                       and anchor not in anchors(linked)):
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, "; ".join(broken)


WORK_ITEM = re.compile(r"\bissues? #?\d+", re.I)  # the project's tracker, not its content


def test_code_scenarios_and_manual_speak_of_the_project_not_of_its_tracker():
    """What a user reads (code, scenario and preset comments, the manual) explains itself;
    the history of its making lives in git and the notebook."""
    files = [*MANUAL, *(path for folder in ("ato_nodes", "scripts", "benchmarks", "launch")
                        for path in (ROOT / folder).rglob("*.py")),
             *(ROOT / "msg_config").rglob("*.yaml")]
    found = [f"{path.relative_to(ROOT)}:{number}" for path in files
             for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if WORK_ITEM.search(line)]
    assert not found, "names a tracker item: " + ", ".join(found)
