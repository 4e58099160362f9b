"""The one YAML reader (common.yaml_io): aliases may not nest past its depth cap, and a file holding
control characters, as a binary file does, is a one-line refusal naming the file, from every command."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.curriculum.cli import main
from common.errors import ConfigError
from common.yaml_io import MAX_DEPTH, parse_yaml, read_yaml

TINY = Path(__file__).parent / "data" / "tiny_curriculum.yaml"


def _alias_chain(links: int) -> str:
    """A document whose last anchor is a list in a list ... ``links`` deep, built by aliases alone:
    every line is shallow, so only the expanded depth is deep."""
    lines = ["a0: &a0 [1]", *(f"a{i}: &a{i} [*a{i - 1}]" for i in range(1, links))]
    return "\n".join(lines) + "\n"


def test_aliases_nesting_within_the_cap_are_read():
    data = parse_yaml(_alias_chain(MAX_DEPTH // 2))
    value, depth = data[f"a{MAX_DEPTH // 2 - 1}"], 0
    while isinstance(value, list):
        value, depth = value[0], depth + 1
    assert (value, depth) == (1, MAX_DEPTH // 2)


@pytest.mark.parametrize("links", [MAX_DEPTH + 1, 3000])
def test_aliases_nesting_past_the_cap_are_refused(links):
    with pytest.raises(ConfigError, match=rf"c.yaml: line \d+: aliases nest deeper than {MAX_DEPTH} levels; refused"):
        parse_yaml(_alias_chain(links), "c.yaml")


def test_a_curriculum_nesting_aliases_past_the_cap_is_a_one_line_error(tmp_path, capsys):
    path = tmp_path / "deep.yaml"
    path.write_text(_alias_chain(3000) + TINY.read_text())
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(path) in err and "aliases nest deeper than" in err, err


# -- control characters --------------------------------------------------------------------------


BINARY_LIKE = {
    "control characters": b"name: tiny\n\x00\x01\x02\n",
    "control characters in a value": b"name: ti\x01ny\nseed: 0\n",
    "an escaped NUL in a path": TINY.read_bytes().replace(b"{kind: sparse}", b'{file: "worlds/a\\0b.yaml"}'),
    "bytes that are not UTF-8": b"\xff\xfe\x00\x01\x02\x03",
}


@pytest.mark.parametrize("case", sorted(BINARY_LIKE))
@pytest.mark.parametrize("command", ["validate", "run"])
def test_a_curriculum_file_with_control_characters_is_a_one_line_error(case, command, tmp_path, capsys):
    path = tmp_path / "binary.yaml"
    path.write_bytes(BINARY_LIKE[case])
    extra = ["--out", str(tmp_path / "run"), "--no-progress"] if command == "run" else []
    assert main([command, str(path), *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {path}: ") and "Traceback" not in err, err
    assert not (tmp_path / "run").exists()  # refused before anything was written


def test_the_reader_names_the_line_and_the_character():
    with pytest.raises(ConfigError, match=r"^c.yaml: line 2: holds the control character #x00, as a binary file does"):
        parse_yaml("name: tiny\n\x00\x01\x02\n", "c.yaml")
    with pytest.raises(ConfigError, match=r"^c.yaml: line 1: a value holds the control character #x00; refused"):
        parse_yaml('file: "a\\0b.yaml"\n', "c.yaml")


def test_text_the_reader_accepts_is_read_unchanged(tmp_path):
    # Tabs, line breaks and non-ASCII letters are text, not control characters.
    path = tmp_path / "fine.yaml"
    path.write_text('name: "t\\tiny"\nnote: "caf\u00e9\\n"\nlines: |\n  one\r\n  two\n')
    assert read_yaml(path) == {"name": "t\tiny", "note": "caf\u00e9\n", "lines": "one\ntwo\n"}


@pytest.mark.parametrize("text, key, lines", [
    ("world: {width: 10, width: 20}\n", "width", "lines 1 and 1"),
    ("name: stage1_2d\nseed: 0\nname: other\n", "name", "lines 1 and 3"),
    ("stages:\n  - budget: 5\n    budget: 6\n", "budget", "lines 2 and 3"),
])
def test_a_key_given_twice_is_refused_naming_both_lines(text, key, lines):
    with pytest.raises(ConfigError, match=f"^f.yaml: line \\d+: the key '{key}' is given twice \\({lines}\\)"):
        parse_yaml(text, "f.yaml")


def test_a_merge_may_still_be_overridden_and_lists_may_repeat_keys():
    text = "base: &b {x: 1, y: 2}\nd:\n  <<: *b\n  x: 5\nitems: [{a: 1}, {a: 2}]\n"
    assert parse_yaml(text) == {"base": {"x": 1, "y": 2}, "d": {"x": 5, "y": 2}, "items": [{"a": 1}, {"a": 2}]}
