"""The documentation: the site builds without a warning (a broken cross-reference, a module the
API reference names that does not exist, a docstring griffe cannot parse), and the Markdown
files at the repository's root link only to files that exist."""

import os
import re
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ROOT_PAGES = ("README.md", "BENCHMARKS.md", "CONTRIBUTING.md", "CHANGELOG.md")
# [text](target) with a relative target: no scheme, no pure #anchor
LINK = re.compile(r"\]\((?!https?://|mailto:|#)([^)\s]+)\)")


def test_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs", reason="the docs build needs the test extra's mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python",
                        reason="the docs build needs mkdocstrings[python]")
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
         os.path.join(ROOT, "mkdocs.yml"), "--site-dir", str(tmp_path / "site")],
        cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    assert (tmp_path / "site" / "api" / "render" / "index.html").exists()


@pytest.mark.parametrize("page", ROOT_PAGES)
def test_root_pages_link_to_existing_files(page):
    path = os.path.join(ROOT, page)
    with open(path, encoding="utf-8") as f:
        text = f.read()
    missing = [target for target in LINK.findall(text)
               if not os.path.exists(os.path.join(ROOT, target.split("#")[0]))]
    assert not missing, f"{page} links to files that do not exist: {missing}"
