"""Bounded input: files and YAML documents of any origin are read within fixed limits, so a
hostile or broken input ends in one clear CsrError, quickly and in little memory, never in a
MemoryError, a RecursionError or minutes of work.

- :func:`read_bounded`: at most :data:`MAX_INPUT_BYTES` bytes from a file or standard input.
- :func:`load_yaml`: YAML through a SafeLoader that refuses more than :data:`MAX_YAML_ALIASES` aliases, nesting
  deeper than :data:`MAX_YAML_DEPTH`, recursive aliases, and documents that would expand (aliases
  counted at the size of what they name -- "billion laughs") to more than :data:`MAX_YAML_NODES`
  nodes. The checks run on the composed node graph, before any Python object is built.
"""
from __future__ import annotations

import sys
from typing import Any, Callable, Dict, List, Optional, Tuple

from ..errors import CsrError
from .fields import clip

MAX_INPUT_BYTES = 8 * 1024 * 1024   # a 5 000-point trajectory dump is about 2 MB
MAX_YAML_ALIASES = 1000
MAX_YAML_DEPTH = 32                 # a waypoint file nests 4 deep, a DisplayTrajectory dump about 8
MAX_YAML_NODES = 1000000            # after alias expansion


def read_bounded(path: str, what: str = "input", limit: int = MAX_INPUT_BYTES) -> bytes:
    """The bytes of ``path`` (``-`` = standard input); CsrError (field ``what``, naming the file)
    if it cannot be read or holds more than ``limit`` bytes. Never reads more than limit + 1."""
    source = "<stdin>" if path == "-" else path
    try:
        if path == "-":
            data = sys.stdin.buffer.read(limit + 1)
        else:
            with open(path, "rb") as f:
                data = f.read(limit + 1)
    except OSError as exc:
        raise CsrError("cannot read: %s" % (exc.strerror or exc), 0, what, source) from None
    if len(data) > limit:
        raise CsrError("larger than %d bytes, the limit for an input file" % limit, 0, what, source)
    return data


class _OverLimit(Exception):
    def __init__(self, reason: str, mark: Any) -> None:
        super().__init__(reason)
        self.reason = reason
        self.line = mark.line + 1 if mark is not None else 0


_BASE: List[Any] = []


def _bounded_loader():
    """The bounded SafeLoader class (made once; yaml is imported on first use)."""
    if _BASE:
        return _BASE[0]
    import yaml
    from yaml.nodes import MappingNode, SequenceNode

    class BoundedLoader(yaml.SafeLoader):
        def __init__(self, stream: Any) -> None:
            super().__init__(stream)
            self._aliases = 0
            self._depth = 0

        def compose_node(self, parent: Any, index: Any) -> Any:
            if self.check_event(yaml.AliasEvent):
                self._aliases += 1
                if self._aliases > MAX_YAML_ALIASES:
                    raise _OverLimit("more than %d YAML aliases (*name)" % MAX_YAML_ALIASES,
                                     self.peek_event().start_mark)
            self._depth += 1
            try:
                if self._depth > MAX_YAML_DEPTH:
                    raise _OverLimit("nested deeper than %d levels" % MAX_YAML_DEPTH, self.peek_event().start_mark)
                return super().compose_node(parent, index)
            finally:
                self._depth -= 1

        def compose_document(self) -> Any:
            node = super().compose_document()
            if node is not None:
                _check_expansion(node)
            return node

    def _check_expansion(root: Any) -> None:
        """Size and depth of the document as it would be built, aliases expanded. Each node is
        visited once (memoised; an anchor comes before its aliases in document order), so this
        costs the size of the text, not of the expansion, and recurses at most the text's depth."""
        done: Dict[int, Tuple[int, int]] = {}      # id(node) -> (expanded size, expanded depth)
        active = set()

        def visit(node: Any) -> Tuple[int, int]:
            key = id(node)
            if key in done:
                return done[key]
            if key in active:
                raise _OverLimit("a recursive YAML alias (a node that contains itself)", node.start_mark)
            if isinstance(node, SequenceNode):
                children = node.value
            elif isinstance(node, MappingNode):
                children = [n for pair in node.value for n in pair]
            else:
                done[key] = (1, 1)
                return done[key]
            active.add(key)
            size, depth = 1, 1
            for child in children:
                s, d = visit(child)
                size, depth = size + s, max(depth, d + 1)
                if size > MAX_YAML_NODES:
                    raise _OverLimit("the YAML aliases expand to more than %d values" % MAX_YAML_NODES,
                                     node.start_mark)
                if depth > MAX_YAML_DEPTH:
                    raise _OverLimit("the YAML aliases nest deeper than %d levels" % MAX_YAML_DEPTH,
                                     node.start_mark)
            active.discard(key)
            done[key] = (size, depth)
            return done[key]

        visit(root)

    _BASE.append(BoundedLoader)
    return BoundedLoader


def load_yaml(text: str, source: str = "", what: str = "input",
              constructors: Optional[Dict[str, Callable[..., Any]]] = None) -> List[Any]:
    """Every non-empty document of ``text``, loaded by a bounded SafeLoader (see the module
    docstring) with ``constructors`` (tag -> function) added. CsrError naming ``source``, the
    line and ``what`` for invalid YAML or an input over a limit."""
    import yaml
    loader = _bounded_loader()
    if constructors:
        loader = type("Loader", (loader,), {})
        for tag, func in constructors.items():
            loader.add_constructor(tag, func)
    try:
        return [d for d in yaml.load_all(text, Loader=loader) if d is not None]
    except _OverLimit as exc:
        raise CsrError("%s, the limit for an input" % exc.reason, exc.line, what, source) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        reason = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        if len(reason) > 120:
            reason = reason[:117] + "..."
        raise CsrError("not valid YAML: %s" % reason, mark.line + 1 if mark else 0, what, source) from None
    except ValueError as exc:    # e.g. an integer too long to convert (Python 3.11 limits int("9" * 5000))
        raise CsrError("a value cannot be read: %s" % clip(str(exc), 120), 0, what, source) from None
