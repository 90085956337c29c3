"""Every node's parameter file holds its dataclass's names and defaults; every parameter is
described, with a range that holds its default, and listed once in the README.

The parameter files in config/ are what users copy and pass with ``--params-file``; the nodes
read none of them unasked, so a file that drifts from the dataclass would make the same node
behave differently by entry point (as the optimizer's prior_weight once did: 0.05 in the file,
0.01 in the dataclass).
"""

from __future__ import annotations

import math
import re
from collections import Counter
from pathlib import Path

import pytest
from node_parameters import EXAMPLES, NODES, declared_parameters, node_specs

from hiros_core.parameters import load_config_defaults

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "config"


def readme_parameters() -> Counter[tuple[str, str]]:
    """``(node, name)`` of every parameter the README's tables list, with how often.

    The tables of its "Parameters" section: the first column names the nodes, the second the
    parameters (in backticks).
    """
    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text[text.index("### Parameters") : text.index("### Topics and diagnostics")]
    listed: Counter[tuple[str, str]] = Counter()
    for line in section.splitlines():
        cells = [cell.strip() for cell in line.split("|")[1:-1]]
        if len(cells) < 3 or cells[0] in {"node", ""} or cells[0].startswith("---"):
            continue
        for node in cells[0].split(","):
            for name in re.findall(r"`([\w.]+)`", cells[1]):
                listed[node.strip(), name] += 1
    return listed


@pytest.mark.parametrize("node", sorted(NODES))
def test_the_parameter_file_holds_every_name_and_default(node: str) -> None:
    specs = node_specs(node)
    values = load_config_defaults(node, CONFIG / f"{node}.yaml")
    assert set(values) <= set(specs), f"{node}.yaml has names the node lacks"
    assert {name: values[name] for name in values} == {name: specs[name].default for name in values}
    # Nested stage parameters (pipeline's tracker.*) may be left to the stages' own files.
    top_level = {name for name in specs if "." not in name}
    assert top_level <= set(values), f"{node}.yaml lacks {sorted(top_level - set(values))}"


@pytest.mark.parametrize(("example", "node"), sorted(EXAMPLES.items()))
def test_an_example_file_uses_the_node_s_names(example: str, node: str) -> None:
    values = load_config_defaults(example, CONFIG / f"{example}.yaml")
    assert set(values) == {name for name in node_specs(node) if "." not in name}


def test_every_file_belongs_to_a_node() -> None:
    files = {path.stem for path in CONFIG.glob("*.yaml")}
    assert files == set(NODES) | set(EXAMPLES)


@pytest.mark.parametrize("node", sorted(NODES))
def test_every_parameter_is_described_and_its_default_allowed(node: str) -> None:
    for spec in node_specs(node).values():
        assert spec.description, f"{node}: {spec.name} has no description"
        assert spec.check(spec.default) == "", spec.name
        if spec.limits is not None:
            low, high = spec.limits
            assert low <= high
            assert not math.isnan(low)
            assert not math.isnan(high)
        descriptor = spec.descriptor()
        assert descriptor.read_only == spec.read_only
        assert descriptor.description == spec.description


@pytest.mark.parametrize("node", sorted(NODES))
def test_topics_qos_and_layout_are_read_only(node: str) -> None:
    fixed = {"input_topic", "output_topic", "input_topics", "camera_topic", "topics",
             "input_qos", "camera_qos", "cameras", "camera_names", "layout", "input"}  # fmt: skip
    for spec in node_specs(node).values():
        if spec.name in fixed:
            assert spec.read_only, f"{node}: {spec.name} is not read-only"


def test_every_parameter_is_listed_once_in_the_readme() -> None:
    """Each node's parameters are in README's user or expert settings, once; nothing else is."""
    listed = readme_parameters()
    declared = {(node, name) for node in {*NODES, *EXAMPLES} for name in declared_parameters(node)}
    assert sorted(declared - set(listed)) == [], "parameters the README does not list"
    assert sorted(set(listed) - declared) == [], "the README lists parameters no node has"
    assert [key for key, count in listed.items() if count > 1] == []
