"""The README stays a newcomer's page: short, its links resolve, and CI runs exactly its test command."""
import re
from pathlib import Path

PROJECT = Path(__file__).resolve().parent.parent
README_MAX_LINES = 200  # issue 24: depth goes to docs/


def test_readme_is_short_and_its_links_resolve():
    text = (PROJECT / "README.md").read_text()
    assert len(text.splitlines()) <= README_MAX_LINES
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not target.startswith("http"):
            assert (PROJECT / target).exists(), f"README links to missing {target}"


def test_ci_runs_the_readme_test_command():
    readme = (PROJECT / "README.md").read_text()
    block = re.search(r"## Tests\s+```bash\n(.+?)\n```", readme, re.S).group(1).strip()
    ci_lines = [line.strip() for line in (PROJECT / ".ci" / "run").read_text().splitlines()]
    assert block in ci_lines, f"README's test command {block!r} is not run verbatim by .ci/run"
