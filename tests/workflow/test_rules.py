"""Every rule passes every file it declares: a stage finds no input by name.

Read from the rule files as written (``workflow/rules/*.smk``), so that a rule that declares an
input for Snakemake's DAG but lets its job find the file again is caught before it runs.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

RULES = Path(__file__).resolve().parents[2] / "workflow" / "rules"

# the campaign page reads each trial's results folder it lists: its inputs are the trial pages
# (so it follows them) and the campaign; the trials' files reach it through those folders.
READS_FOLDERS = {"report_campaign": {"trial pages"}}


def _sections(block: str) -> dict[str, str]:
    """A rule's sections (input, output, shell, ...) by name, as written."""
    parts = re.split(r"(?m)^    (\w+):[ \t]*\n?", block)
    return {parts[i]: parts[i + 1] for i in range(1, len(parts) - 1, 2)}


def rules() -> dict[str, dict[str, str]]:
    """``{rule: {section: text}}`` of every rule in workflow/rules/."""
    out = {}
    for f in sorted(RULES.glob("*.smk")):
        for block in re.split(r"(?m)^(?=rule )", f.read_text())[1:]:
            name = re.match(r"rule (\w+):", block).group(1)
            out[name] = _sections(block)
    return out


def declared_inputs(rule: dict[str, str]) -> tuple[list[str], int]:
    """(the named inputs, the number of unnamed ones) of a rule's input section."""
    names, unnamed = [], 0
    depth = 0
    for line in rule.get("input", "").splitlines():
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if depth == 0:
            m = re.match(r"(\w+)=", s)
            if m:
                names.append(m.group(1))
            else:
                unnamed += 1
        depth += s.count("(") - s.count(")") + s.count("[") - s.count("]")
    return names, unnamed


def test_the_rules_are_read():
    found = rules()
    assert {"decode", "calibrate", "sync", "sweep", "track", "estimate", "plan", "report_trial"} <= set(found)
    names, unnamed = declared_inputs(found["estimate"])
    assert {"tracks", "joints", "geometry", "clock", "tracking", "prev"} <= set(names) and unnamed == 0
    assert declared_inputs(found["report_campaign"])[1] == 1


@pytest.mark.parametrize("name", sorted(rules()))
def test_every_declared_input_reaches_the_command(name):
    rule = rules()[name]
    shell = rule.get("shell", "")
    assert shell, f"rule {name} has no shell command"
    names, unnamed = declared_inputs(rule)
    missing = [n for n in names if not re.search(r"\{input\." + n + r"(:q)?\}", shell)]
    assert not missing, f"rule {name} declares {missing} but its command does not pass them"
    if unnamed:
        assert name in READS_FOLDERS, f"rule {name} has an unnamed input its command cannot name"


def test_no_rule_passes_a_trial_folder_to_a_stage():
    """A stage reads the files its rule names, never a folder it searches (the campaign page aside)."""
    for name, rule in rules().items():
        if name in READS_FOLDERS:
            continue
        assert "--trial-dir" not in rule.get("shell", "") and "--data-dir" not in rule.get("shell", ""), name


def _command(shell: str) -> str | None:
    """The stringcast subcommand a rule's shell runs (the word after ``--log "{log}"``)."""
    m = re.search(r'--log "\{log\}" ([\w-]+)', shell)
    return m.group(1) if m else None


@pytest.mark.parametrize("name", sorted(rules()))
def test_each_rule_passes_its_commands_inputs_under_their_one_name(name):
    """The contract (stringcast.core.ports.INPUTS) and the rules agree: a rule passes every input of
    its command, each as ``--<name> {input.<name>}``, and no input file the contract does not list."""
    from stringcast.core import INPUTS

    shell = rules()[name].get("shell", "")
    command = _command(shell)
    if command not in INPUTS:
        pytest.skip(f"rule {name} runs no stage command")
    passed = re.findall(r'(--[\w-]+) "?\{input\.(\w+)(?::q)?\}', shell)
    for flag, input_name in passed:
        assert flag == "--" + input_name.replace("_", "-"), f"rule {name}: {flag} passes input.{input_name}"
    got, listed = sorted(n for _, n in passed), sorted(p.name for p in INPUTS[command])
    assert got == listed, f"rule {name} passes {got}, the contract lists {listed}"
