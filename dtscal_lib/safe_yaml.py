"""Load a small YAML data file with limits, so that a hostile file cannot hang or exhaust the kit.

``yaml.safe_load`` runs no code, but it trusts the document's size: 1 KB of nested
aliases (``&a [*b, *b, ...]``) expands to billions of values when the result is walked,
a 5000-digit integer raises ``ValueError`` inside PyYAML, and a duplicated key silently
keeps the last value. :func:`load_yaml_file` adds the limits a calibration file needs:

* the file is a regular file (never a FIFO or a device) of at most :data:`MAX_FILE_BYTES`;
* the document, with every alias expanded, has at most :data:`MAX_NODES` nodes (harmless
  aliases still load; an alias bomb is refused before anything is built) and nests at most
  :data:`MAX_DEPTH` levels deep;
* no scalar is longer than :data:`MAX_SCALAR_CHARS`; integers have at most
  :data:`MAX_INT_DIGITS` digits and floats are range-checked before conversion;
* no mapping repeats a key.

Refusals are :class:`~dtscal_lib.errors.CalibrationFileError` naming the file, the field
(``camera_matrix.data[3]``) and the line, with the offending text cut to a readable length.
YAML syntax errors and non-data tags come out of PyYAML as ``yaml.YAMLError`` for the
caller to word.

>>> load_yaml_text("a: &x [1, 2]\\nb: *x\\n", "demo.yaml")
{'a': [1, 2], 'b': [1, 2]}
>>> load_yaml_text("a: 1\\na: 2\\n", "demo.yaml")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
dtscal_lib.errors.CalibrationFileError: demo.yaml: field 'a' appears twice (line 2); ...
"""

from __future__ import annotations

import os
import re
import stat
from typing import Any

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from .errors import CalibrationFileError

#: largest YAML file read (a calibration file is about 1 KB)
MAX_FILE_BYTES = 64 * 1024
#: most nodes in a document, every alias counted as the size of what it refers to
MAX_NODES = 10_000
#: deepest nesting of lists and mappings (a calibration file nests 2 deep; PyYAML composes recursively)
MAX_DEPTH = 32
#: longest scalar (string or number) in characters
MAX_SCALAR_CHARS = 4096
#: most digits of an integer (a 64-bit integer has 20)
MAX_INT_DIGITS = 30
#: longest text of a float (a double needs 17 significant digits and an exponent)
MAX_FLOAT_CHARS = 64
#: longest message quote of the file's content
QUOTE_CHARS = 60

_INT_TAG = "tag:yaml.org,2002:int"
_FLOAT_TAG = "tag:yaml.org,2002:float"


def shorten(text: str, limit: int = QUOTE_CHARS) -> str:
    """``text`` cut to ``limit`` characters with the cut said.

    >>> shorten("9" * 500, 12)
    '999999999999… (500 characters)'
    """
    text = str(text)
    return text if len(text) <= limit else f"{text[:limit]}… ({len(text)} characters)"


def _fail(where: str, msg: str) -> CalibrationFileError:
    return CalibrationFileError(f"{where}: {msg}")


def _line(node: Node) -> str:
    mark = node.start_mark
    return f"line {mark.line + 1}" if mark is not None else "the document"


class _BoundedLoader(yaml.SafeLoader):
    """SafeLoader that sizes every node as it is composed (aliases count as their target)."""

    def __init__(self, stream, where: str):
        super().__init__(stream)
        self.where = where
        self.sizes: dict[int, int] = {}
        self.depth = 0

    def compose_node(self, parent, index):
        alias = self.check_event(yaml.AliasEvent)
        if self.depth >= MAX_DEPTH:
            mark = self.peek_event().start_mark
            raise _fail(self.where, f"the YAML document nests more than {MAX_DEPTH} levels deep (line "
                                    f"{mark.line + 1}); a calibration file nests 2 levels: fix the file or restore "
                                    "it from default.yaml")
        self.depth += 1
        try:
            node = super().compose_node(parent, index)
        finally:
            self.depth -= 1
        if alias:
            size = self.sizes.get(id(node))
            if size is None:
                raise _fail(self.where, f"a YAML alias refers to a structure that contains it ({_line(node)}); "
                                        "a calibration file cannot be recursive")
            return node
        if isinstance(node, SequenceNode):
            size = 1 + sum(self.sizes[id(c)] for c in node.value)
        elif isinstance(node, MappingNode):
            size = 1 + sum(self.sizes[id(k)] + self.sizes[id(v)] for k, v in node.value)
        else:
            size = 1
        if size > MAX_NODES:
            raise _fail(self.where, f"the YAML document expands to more than {MAX_NODES} values ({_line(node)}), "
                                    "far more than a calibration file holds (an alias bomb?); the file was not loaded")
        self.sizes[id(node)] = size
        return node


def _check_scalar(node: ScalarNode, path: str, where: str) -> None:
    value = node.value
    if node.tag == _INT_TAG:
        digits = len(re.sub(r"[^0-9a-fA-F]", "", value))
        if digits > MAX_INT_DIGITS:
            raise _fail(where, f"field {path!r} is an integer of {digits} digits ({_line(node)}: "
                               f"{shorten(value)}); no calibration value has more than {MAX_INT_DIGITS}: "
                               "fix the file or restore it from default.yaml")
    elif node.tag == _FLOAT_TAG and len(value) > MAX_FLOAT_CHARS:
        raise _fail(where, f"field {path!r} is a number written with {len(value)} characters ({_line(node)}: "
                           f"{shorten(value)}); write it with at most 17 significant digits")
    elif len(value) > MAX_SCALAR_CHARS:
        raise _fail(where, f"field {path!r} is {len(value)} characters long ({_line(node)}); the limit is "
                           f"{MAX_SCALAR_CHARS}")


def _key_text(node: Node) -> str:
    return shorten(node.value, 40) if isinstance(node, ScalarNode) else f"<{type(node).__name__}>"


def check_tree(root: Node, where: str) -> None:
    """Refuse duplicate keys and oversized numbers anywhere in a composed document."""
    stack: list[tuple[Node, str]] = [(root, "")]
    while stack:
        node, path = stack.pop()
        if isinstance(node, ScalarNode):
            _check_scalar(node, path or "(document)", where)
        elif isinstance(node, SequenceNode):
            stack.extend((child, f"{path}[{i}]") for i, child in enumerate(node.value))
        elif isinstance(node, MappingNode):
            seen: set[tuple[str, str]] = set()
            for key, value in node.value:
                name = _key_text(key)
                sub = f"{path}.{name}" if path else name
                if isinstance(key, ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
                    ident = (key.tag, key.value)
                    if ident in seen:
                        raise _fail(where, f"field {sub!r} appears twice ({_line(key)}); a calibration file names "
                                           "each field once: remove the duplicate")
                    seen.add(ident)
                stack.append((key, f"{sub} (key)"))
                stack.append((value, sub))


def load_yaml_text(text: str, where: str) -> Any:
    """Parse one YAML document with the limits of this module; None for an empty document.

    Raises
    ------
    CalibrationFileError
        A limit is exceeded (document size, alias expansion, number length, duplicate key).
    yaml.YAMLError
        Invalid YAML, or a tag that is not plain data.
    """
    if len(text) > MAX_FILE_BYTES:
        raise _fail(where, f"is {len(text)} characters long; a calibration file has at most {MAX_FILE_BYTES}")
    loader = _BoundedLoader(text, where)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        check_tree(node, where)
        return loader.construct_document(node)
    finally:
        loader.dispose()


def read_text_file(path: str | os.PathLike, where: str | None = None, limit: int = MAX_FILE_BYTES) -> str:
    """The UTF-8 text of a small regular file; FIFOs, devices and files over ``limit`` bytes are refused."""
    where = where or os.fspath(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
    except FileNotFoundError:
        raise _fail(where, "file not found") from None
    except OSError as err:
        raise _fail(where, f"cannot be read ({err.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _fail(where, "is not a regular file (a folder, FIFO or device); pass the calibration YAML file")
        if st.st_size > limit:
            raise _fail(where, f"is {st.st_size} bytes; a calibration file is a few KB (limit {limit} bytes): "
                               "pass the right file")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(limit + 1)
    except OSError as err:
        raise _fail(where, f"cannot be read ({err.strerror})") from None
    finally:
        os.close(fd)
    if len(data) > limit:
        raise _fail(where, f"is more than {limit} bytes; a calibration file is a few KB")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise _fail(where, f"is not UTF-8 text (byte {err.start}); pass the calibration YAML file") from None


def load_yaml_file(path: str | os.PathLike, where: str | None = None) -> Any:
    """:func:`read_text_file` then :func:`load_yaml_text`."""
    where = where or os.fspath(path)
    return load_yaml_text(read_text_file(path, where), where)


__all__ = ["load_yaml_file", "load_yaml_text", "read_text_file", "check_tree", "shorten", "MAX_FILE_BYTES",
           "MAX_NODES", "MAX_INT_DIGITS"]
