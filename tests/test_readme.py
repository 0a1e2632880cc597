"""The README's Python quickstart runs as written, and the README cites only the project's
own documents."""

import os
import re

ROOT = os.path.join(os.path.dirname(__file__), "..")


def _readme() -> str:
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as f:
        return f.read()


def test_quickstart_block_runs(capsys):
    text = _readme()
    quickstart = text[text.index("## Quickstart") :]
    block = re.search(r"```python\n(.*?)```", quickstart, re.S).group(1)
    exec(compile(block, "README.md (quickstart)", "exec"), {"__name__": "__readme__"})
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) >= 3 and int(lines[-1]) > 0  # the last line: groups found with sigma="auto"


def test_readme_links_exist_and_cite_no_outside_document():
    text = _readme()
    assert "SPEC" not in text
    for target in re.findall(r"\]\(([^)#]+)\)", text):
        if not target.startswith("http"):
            assert os.path.exists(os.path.join(ROOT, target)), target
    for path in (
        "docs/CONVENTIONS.md",
        "docs/BENCHMARK.md",
        "docs/ALGORITHM.md",
        "LICENSE",
        "examples/rig.json",
        "examples/detections.json",
    ):
        assert path in text and os.path.exists(os.path.join(ROOT, path)), path
