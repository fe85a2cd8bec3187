"""Writing a .csr program: text, bytes in an encoding, and a file replaced atomically."""
from __future__ import annotations

import os
import tempfile
from typing import List, Tuple

from ..errors import CsrError
from .fields import show
from .model import CsrProgram, check_structure


def format_program(program: CsrProgram, newline: str = "\r\n") -> str:
    """The program as text (``newline`` "\\r\\n" or "\\n"); CsrError if it is inconsistent."""
    if newline not in ("\r\n", "\n"):
        raise CsrError("newline must be CRLF or LF, got %s" % show(newline), field="newline")
    check_structure(program)
    sections: List[Tuple[str, List[str]]] = []

    def extras(after: str) -> None:
        for raw in program.extra_sections:
            if raw.after == after:
                sections.append((raw.name, list(raw.lines)))

    extras("")
    sections.append(("Description", program.description.lines()))
    extras("Description")
    header = "/Name, Type, " + ", ".join(program.columns())
    sections.append(("Pose", [header] + [", ".join([p.name, p.kind] + p.fields(program.decimals))
                                         for p in program.poses]))
    extras("Pose")
    if program.variables is not None:
        sections.append(("Variable", [v.line_text() for v in program.variables]))
    extras("Variable")
    sections.append(("Command", [c.line_text() for c in program.commands]))
    extras("Command")
    out: List[str] = []
    for k, (name, lines) in enumerate(sections):
        if k:
            out.append("")
        out.append("[%s]" % name)
        out.extend(lines)
    return newline.join(out) + newline


def program_bytes(program: CsrProgram, newline: str = "\r\n", encoding: str = "ascii") -> bytes:
    text = format_program(program, newline)
    try:
        return text.encode(encoding)
    except UnicodeEncodeError as exc:
        bad = text[exc.start:exc.end]
        line = text.count("\n", 0, exc.start) + 1
        raise CsrError("%s cannot be written in %s" % (show(bad), encoding), line, "text") from None


def write_program(program: CsrProgram, path: str, newline: str = "\r\n", encoding: str = "ascii") -> None:
    """Write atomically (a temporary file in the same directory, then renamed): a failed export
    never leaves half a file, and a second export replaces the first (never appends)."""
    _atomic_write(program_bytes(program, newline, encoding), path)


def _atomic_write(data: bytes, path: str) -> None:
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".csr-", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
