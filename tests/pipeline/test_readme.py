"""The README cannot drift from the code: its set-up commands, every ``cgfem`` command it
shows (parsed by the real argument parser, the quick start run for real), every path and
link it names (in ``docs/`` too), and every result field its tables list."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import meshio
import pytest

from cgfem.cli import build_parser, main

from tests.support.paths import REPO

README = REPO / "README.md"
#: the two set-up commands, unchanged in effect
SETUP = ('python3 -m pip install -e . && snakemake --cores 2',
         'python3 -m pip install -e ".[test]" && python3 -m pytest -q -n 2 --dist loadfile')
MAX_LINES = 250


def markdown_files() -> list[Path]:
    return [README, REPO / "CHANGELOG.md", *sorted((REPO / "docs").rglob("*.md"))]


def code_blocks(text: str) -> list[str]:
    return re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S)


def cgfem_commands(text: str) -> list[list[str]]:
    """The ``cgfem ...`` command lines of the code blocks (comments dropped)."""
    commands = []
    for block in code_blocks(text):
        for line in block.splitlines():
            line = line.split("#", 1)[0].strip()
            if line.startswith("cgfem "):
                commands.append(shlex.split(line)[1:])
    return commands


def anchors(path: Path) -> set[str]:
    """GitHub's anchors of the headings of a Markdown file."""
    out = set()
    for heading in re.findall(r"^#+\s+(.*)$", path.read_text(), flags=re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
        out.add(slug)
    return out


def test_readme_is_short_and_starts_with_the_two_setup_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= MAX_LINES
    first_blocks = [b.strip() for b in code_blocks(text)[:2]]
    assert first_blocks == list(SETUP)


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_every_link_resolves(path):
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+://", target) or target.startswith("mailto:"):
            continue
        file, _, anchor = target.partition("#")
        resolved = (path.parent / file).resolve() if file else path
        if not resolved.exists():
            broken.append(target)
        elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
            broken.append(target)
    assert not broken, f"{path.relative_to(REPO)}: broken links {broken}"


def test_every_cgfem_command_parses():
    commands = cgfem_commands(README.read_text())
    assert {c[0] for c in commands} >= {"check", "run"}
    parser = build_parser()
    for argv in commands:
        parser.parse_args(argv)            # SystemExit (a failed test) on an unknown option


def test_the_command_table_names_only_real_options():
    text = README.read_text()
    section = text.split("## The command line", 1)[1].split("\n## ", 1)[0]
    parser = build_parser()
    sub = {a.dest: a for a in parser._subparsers._group_actions}["command"].choices
    for name, options in re.findall(r"`cgfem (\w+)([^`]*)`", section):
        assert name in sub, name
        known = {s for a in sub[name]._actions for s in a.option_strings}
        assert set(re.findall(r"--[a-z][a-z-]*", options)) <= known, (name, options)


def test_named_paths_exist():
    text = README.read_text()
    named = set(re.findall(r"`((?:config|src|tests|benchmarks|workflow|docs|paper_figures)/[^`\s]*)`", text))
    named |= {p for c in cgfem_commands(text) for p in c if p.startswith("config/")}
    missing = [p for p in sorted(named) if not any(REPO.glob(p.replace("{", "*").split("*")[0] + "*"))]
    assert not missing


def test_check_commands_of_the_quick_start_succeed(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(REPO)
    for argv in cgfem_commands(README.read_text()):
        if argv[0] == "check":
            argv = [str(tmp_path / a) if a.startswith("out/") else a for a in argv]
            assert main(argv) == 0, argv


@pytest.mark.slow
def test_quick_start_run_writes_every_field_the_readme_lists(tmp_path, monkeypatch):
    """The quick start's run, to its first step, writes every summary key, step key and VTU
    field the result-file tables name."""
    text = README.read_text()
    run = next(c for c in cgfem_commands(text) if c[0] == "run")
    out = tmp_path / "run"
    argv = [str(out) if a.startswith("out/") else a for a in run]
    monkeypatch.chdir(REPO)
    assert main([*argv, "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    section = text.split("## Result files", 1)[1].split("\n## ", 1)[0]
    keys = set(re.findall(r"`([a-z_]+)`", section.split("Each step:", 1)[0]))
    assert keys - {"summary"} <= set(summary) | set(summary["bodies"][next(iter(summary["bodies"]))])
    step = summary["steps"][0]
    table = section.split("Each step:", 1)[1].split("| file |", 1)[0]
    for row in re.findall(r"^\| `([a-z_]+)`(?:, `([a-z_]+)`)?(?:, `([a-z_]+)`)? \|", table, flags=re.M):
        assert all(k in step for k in row if k), row
    contact = re.search(r"^\| `contact` \| (.*) \|$", table, flags=re.M).group(1)
    assert set(re.findall(r"`([a-z_]+)`", contact)) - {"floating"} <= set(step["contact"])
    files = re.findall(r"^\| `(\w+)_NNN\.vtu`[^|]*\|[^|]*\| (.*) \|$", section, flags=re.M)
    assert {f for f, _ in files} >= {"step", "boundary", "surface", "contact"}
    for prefix, fields in files:
        mesh = meshio.read(out / f"{prefix}_001.vtu")
        have = set(mesh.point_data) | set(mesh.cell_data)
        listed = set(re.findall(r"`([a-z_]+)`", fields))
        assert listed <= have, (prefix, listed - have)
