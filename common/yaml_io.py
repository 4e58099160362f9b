"""The one YAML reader for every file the project reads: curricula, scenarios, IR-SIM worlds, run configs.

Files are shared between people, so reading one must stay cheap whatever it holds. On top of
PyYAML's safe loader (no tags that build Python objects) it refuses, each as a one-line
:class:`ConfigError`:

* files over :data:`MAX_BYTES`;
* anything but a regular file (a device, a FIFO, a directory), read through :mod:`common.files`,
  which never reads past :data:`MAX_BYTES` whatever the file's size header says;
* control characters, in the text (a binary file, say) or escaped in a value (``"\\0"``);
* values the safe loader cannot build (``2024-02-30``, an integer of more than
  :data:`~common.files.MAX_DIGITS` digits, which Python will not convert to or from text);
* nesting deeper than :data:`MAX_DEPTH` (PyYAML's composer recurses and would overflow);
* documents of more than :data:`MAX_NODES` values, counted as they are composed (a 2 MiB file
  of a million numbers took 20 s and 800 MB to compose; now 0.7 s and 75 MB to refuse);
* documents whose aliases would expand past :data:`MAX_NODES` values (a "billion laughs" file is
  a few hundred bytes that anything walking the data, a validator or an error message, expands
  exponentially), or that refer to themselves.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from common.errors import ConfigError, quote
from common.files import MAX_DIGITS, read_text

MAX_BYTES = 2 * 1024 * 1024
MAX_DEPTH = 48
MAX_NODES = 200_000
_CONTROL = yaml.reader.Reader.NON_PRINTABLE  # what YAML refuses in a file's text
_TOO_LARGE_INT = 10**MAX_DIGITS  # a hexadecimal or octal literal builds one without Python's digit limit


class _Refused(Exception):
    """Why a document was refused, and where."""

    def __init__(self, problem: str, mark: yaml.Mark | None = None) -> None:
        super().__init__(problem)
        self.problem = problem
        self.line = mark.line + 1 if mark is not None else None


# libyaml's parser (PyYAML's C extension), when installed, turns text into events about five times
# as fast as PyYAML's own; either way the composer, resolver and constructor are PyYAML's Python ones,
# so the bounds below apply alike. Marks (the lines errors name) come from either parser.
_Parser = getattr(getattr(yaml, "_yaml", None), "CParser", None) if yaml.__with_libyaml__ else None


class _BoundedLoader(yaml.composer.Composer, *((_Parser,) if _Parser else (yaml.reader.Reader, yaml.scanner.Scanner, yaml.parser.Parser)),
                     yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
    """A safe loader whose composer refuses deep nesting before it recurses into it, and a
    document of more than :data:`MAX_NODES` values before it composes the rest (composing is
    the costly part: a 2 MiB list of a million numbers took 20 s and 800 MB)."""

    def __init__(self, stream: str) -> None:
        if _Parser:
            _Parser.__init__(self, stream)
        else:
            yaml.reader.Reader.__init__(self, stream)
            yaml.scanner.Scanner.__init__(self)
            yaml.parser.Parser.__init__(self)
        yaml.composer.Composer.__init__(self)
        yaml.constructor.SafeConstructor.__init__(self)
        yaml.resolver.Resolver.__init__(self)
        self._depth = 0
        self._nodes = 0
        self.aliases = 0  # without any, the document is its nodes: no expansion to check

    def compose_node(self, parent, index):
        self._depth += 1
        self._nodes += 1
        if self._depth > MAX_DEPTH:
            raise _Refused(f"nested deeper than {MAX_DEPTH} levels", self.peek_event().start_mark)
        if self._nodes > MAX_NODES:
            raise _Refused(f"holds more than {MAX_NODES:,} values", self.peek_event().start_mark)
        if self.check_event(yaml.AliasEvent):
            self.aliases += 1
        try:
            node = super().compose_node(parent, index)
        finally:
            self._depth -= 1
        if isinstance(node, yaml.ScalarNode) and (control := _CONTROL.search(node.value)):
            raise _Refused(f"a value holds the control character #x{ord(control.group()):02x}", node.start_mark)
        return node

    def construct_mapping(self, node, deep=False):
        """A mapping; a key written twice in it is refused (PyYAML keeps the last one without a
        word, so ``width: 10`` then ``width: 20`` was a 20 m world). Keys a merge (``<<``) brings
        in may still be overridden, as YAML means them to be."""
        if isinstance(node, yaml.MappingNode):
            lines: dict[tuple[str, str], int] = {}
            for key_node, _ in node.value:
                if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key, line = (key_node.tag, key_node.value), key_node.start_mark.line + 1
                if key in lines:
                    raise _Refused(f"the key {quote(key_node.value)} is given twice (lines {lines[key]} and {line})",
                                   key_node.start_mark)
                lines[key] = line
        return super().construct_mapping(node, deep)

    def construct_object(self, node, deep=False):
        """A node's value; a scalar the safe loader cannot build (``2024-02-30``, an integer past
        Python's digit limit) is refused naming its line, not a ValueError from deep inside PyYAML."""
        try:
            value = super().construct_object(node, deep)
        except (yaml.YAMLError, _Refused):
            raise
        except Exception as exc:
            if not isinstance(node, yaml.ScalarNode):
                raise
            # PyYAML's standard constructors fail on what they cannot read in many ways: `!!bool
            # maybe` a KeyError, `!!int +` an IndexError, `!!timestamp hello` an AttributeError.
            kind = {"timestamp": "date"}.get(node.tag.rsplit(":", 1)[-1], node.tag.rsplit(":", 1)[-1])
            if kind == "int" and node.value.lstrip("+-").replace("_", "").isdigit():
                problem = f"an integer of more than {MAX_DIGITS} digits"
            elif isinstance(exc, (ValueError, OverflowError)):
                reason = str(exc).split(":")[0][:80]
                problem = f"{quote(node.value)} is not a valid {kind} ({reason})"
            else:
                problem = f"{quote(node.value)} is not a valid {kind}"
            raise _Refused(problem, node.start_mark) from None
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= _TOO_LARGE_INT:
            raise _Refused(f"an integer of more than {MAX_DIGITS} digits", node.start_mark)
        return value


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [part for pair in node.value for part in pair]
    return []


def _check_expansion(root: yaml.Node) -> None:
    """Count the values the node graph expands to (aliases followed), without expanding it.

    A node reached through several aliases is counted once per path, with its size memoised, so
    the count is exact and the walk linear in the number of distinct nodes. A cycle is refused, and
    so is a value escaping a control character the reader refuses in the text (``"\\0"``): no
    field holds one, and a NUL in a path is a ValueError deep inside whatever opens it.
    """
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            on_path.discard(key)
            if isinstance(node, yaml.ScalarNode) and (control := _CONTROL.search(node.value)):
                raise _Refused(f"a value holds the control character #x{ord(control.group()):02x}", node.start_mark)
            children = _children(node)
            size[key] = 1 + sum(size[id(c)] for c in children)
            depth[key] = 1 + max((depth[id(c)] for c in children), default=0)
            if size[key] > MAX_NODES:
                raise _Refused(f"aliases expand to more than {MAX_NODES:,} values", node.start_mark)
            if depth[key] > MAX_DEPTH:
                raise _Refused(f"aliases nest deeper than {MAX_DEPTH} levels", node.start_mark)
            continue
        if key in size:
            continue
        if key in on_path:
            raise _Refused("an alias refers to a value that contains it", node.start_mark)
        on_path.add(key)
        stack.append((node, True))
        stack.extend((child, False) for child in _children(node) if id(child) not in size)


def parse_yaml(text: str, source: str | Path | None = None) -> Any:
    """Parse YAML text within the bounds above; every failure is a one-line :class:`ConfigError`."""
    if len(text) > MAX_BYTES:
        raise ConfigError(source, None, f"larger than {MAX_BYTES // 1024 // 1024} MiB; allowed: smaller YAML files")
    try:
        # PyYAML's reader checks the whole text for control characters as it is built (and
        # refuses more of them than libyaml does): that check, whichever parser reads the text.
        yaml.reader.Reader(text)
        loader = _BoundedLoader(text)
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        problem = f"holds the control character #x{exc.character:02x}, as a binary file does; expected a text YAML file"
        raise ConfigError(source, f"line {line}", problem) from None
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        if loader.aliases:
            _check_expansion(node)
        return loader.construct_document(node)
    except _Refused as refused:
        raise ConfigError(source, f"line {refused.line}" if refused.line else None,
                          f"{refused.problem}; refused") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        # libyaml's scanner, reading ahead, may meet its own nesting limit (1000) before the composer meets ours.
        deep = "nesting depth" in str(getattr(exc, "problem", ""))
        # The parser's own reason says what to fix ("found character '\\t' that cannot start any token").
        reason = " ".join(str(getattr(exc, "problem", "") or "").split())[:200]
        lines = text.splitlines()
        if mark is not None and mark.line < len(lines) and "\t" in lines[mark.line][:mark.column + 1]:
            reason += " (a tab; YAML indents with spaces)"
        problem = f"nested deeper than {MAX_DEPTH} levels; refused" if deep else \
            "not valid YAML" + (f": {reason}" if reason else "")
        if isinstance(exc, yaml.constructor.ConstructorError) and "for the tag " in str(exc.problem):
            # A tag asks the reader to build an object (python/object, say): plain YAML only, nothing runs.
            tag = str(exc.problem).split("for the tag ", 1)[1].replace("tag:yaml.org,2002:", "!!")
            problem = f"the tag {tag} is refused; allowed: plain YAML and YAML's standard !! tags"
        raise ConfigError(source, f"line {mark.line + 1}" if mark is not None else None, problem) from None
    finally:
        loader.dispose()


def read_yaml(path: str | Path) -> Any:
    """Read and parse a YAML file (see :func:`parse_yaml`)."""
    path = Path(path)
    text = read_text(path, MAX_BYTES, "a YAML file", too_large="allowed: smaller YAML files")
    return parse_yaml(text, path)


def read_yaml_mapping(path: str | Path) -> dict:
    """Read a YAML file that must hold a mapping at the top level."""
    data = read_yaml(path)
    if data is None:
        raise ConfigError(path, None, "the file is empty; expected a YAML mapping")
    if not isinstance(data, dict):
        raise ConfigError(path, None, f"expected a YAML mapping at the top level, got {type(data).__name__}")
    return data
