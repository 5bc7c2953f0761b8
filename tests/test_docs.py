"""The docs stay in step with the code: CLI reference, effects reference, links."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from omavctl.physics.effects import EFFECTS

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _load_tool(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "tools" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_is_up_to_date():
    expected = _load_tool("gen_cli_docs").render()
    current = (DOCS / "cli.md").read_text() if (DOCS / "cli.md").exists() else ""
    assert current == expected, "docs/cli.md is stale: run python tools/gen_cli_docs.py"


def _effect_sections() -> dict[str, str]:
    """Sections of docs/effects.md by effect name (headings ``## `name` ``)."""
    text = (DOCS / "effects.md").read_text()
    parts = re.split(r"^## `([a-z0-9_]+)`\s*$", text, flags=re.MULTILINE)
    return {parts[i]: parts[i + 1] for i in range(1, len(parts), 2)}


@pytest.mark.parametrize("name", sorted(EFFECTS))
def test_every_effect_is_documented(name):
    sections = _effect_sections()
    assert name in sections, (
        f"docs/effects.md has no entry for the registered effect '{name}': "
        f"add a section '## `{name}`' (see docs/adding-an-effect.md)"
    )
    body = sections[name]
    for p in EFFECTS[name].parameters:
        assert f"`{p.name}`" in body, f"docs/effects.md, {name}: parameter '{p.name}' missing"
        unit = p.unit.replace("^2", "²")
        assert unit in body or p.unit in body, (
            f"docs/effects.md, {name}: unit '{p.unit}' of '{p.name}' missing"
        )
    for part in ("**Meaning.**", "**Formula.**", "**Simulation form.**"):
        assert part in body, f"docs/effects.md, {name}: no {part} paragraph"


def test_effects_reference_lists_only_registered_effects():
    unknown = sorted(set(_effect_sections()) - set(EFFECTS))
    assert not unknown, f"docs/effects.md documents unregistered effects: {unknown}"


def _anchors(page: Path) -> set[str]:
    """GitHub-style anchors of a Markdown page's headings (outside code blocks)."""
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.MULTILINE | re.DOTALL)
    out = set()
    for heading in re.findall(r"^#+\s+(.+?)\s*$", text, flags=re.MULTILINE):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
        out.add(slug)
    return out


def test_relative_links_in_docs_resolve():
    bad = []
    for page in sorted([*DOCS.glob("*.md"), ROOT / "README.md"]):
        text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.MULTILINE | re.DOTALL)
        for target, anchor in re.findall(r"\]\(([^)#\s]*)(?:#([^)\s]*))?\)", text):
            if "://" in target:
                continue
            path = page.parent / target if target else page
            if not path.exists():
                bad.append(f"{page.relative_to(ROOT)} -> {target}")
            elif anchor and path.suffix == ".md" and anchor not in _anchors(path):
                bad.append(f"{page.relative_to(ROOT)} -> {target}#{anchor}")
    assert not bad, "broken links: " + ", ".join(bad)


def test_index_lists_every_page():
    index = (DOCS / "index.md").read_text()
    missing = [p.name for p in sorted(DOCS.glob("*.md")) if p.name != "index.md"]
    missing = [name for name in missing if f"({name})" not in index]
    assert not missing, f"docs/index.md does not link to: {', '.join(missing)}"


def test_getting_started_quotes_the_demo_numbers_the_tool_generated():
    """docs/getting-started.md quotes the demo's verdict and figures: each span is
    between markers, holds exactly what tools/demo_numbers.py computed from the demo's
    outputs (docs/demo-numbers.json), and no other percentage in the walk-through is
    left to go stale (the demo itself takes minutes: `make demo-numbers` refreshes)."""
    import json

    tool = _load_tool("demo_numbers")
    values = json.loads((DOCS / "demo-numbers.json").read_text())
    doc = (DOCS / "getting-started.md").read_text()
    marked = [m[1] for m in tool.MARKER.finditer(doc)]
    assert set(marked) == set(values), "every generated value is quoted, nothing else marked"
    assert tool.render(doc, values) == doc, "stale: run make demo-numbers"
    # the demo's commands (run in examples/) as the page types them (from the top)
    assert (
        tool._as_typed_in_the_doc(
            "omavctl fit build/flight-01 --effects a,b --out build/gp+b.npz --seed 0"
        )
        == "omavctl fit examples/build/flight-01 --effects a,b --out build/first/gp+b.npz --seed 0"
    )
    # the verdict's plan command names the model the page fitted (build/first/gp.npz)
    # and writes its task and plan beside it, not over the user's files
    assert tool._as_typed_in_the_doc(
        "omavctl task fig8 --out build/gp.fig8.csv && omavctl plan --task build/gp.fig8.csv "
        "--model build/gp.npz --out build/gp.separate.csv"
    ) == (
        "omavctl task fig8 --out build/first/gp.fig8.csv && omavctl plan --task "
        "build/first/gp.fig8.csv --model build/first/gp.npz --out build/first/gp.separate.csv"
    )
    assert "--model build/gp.npz" not in doc
    walk = doc[doc.index("## 3.") : doc.index("## 5.")]
    left = tool.MARKER.sub("", walk)
    # the thresholds the verdict applies and the intervals' level are rules, not demo output
    rules = ("80 %", "90 %", "95 %")
    stray = [p for p in re.findall(r"[−+-]?\d+(?:\.\d+)? ?%", left) if p not in rules]
    assert stray == [], f"demo figures outside the generated spans: {stray}"
