"""Writing a .csr program: text, bytes in an encoding, and a file -- replaced atomically, keeping its
mode, and never replacing anything but a regular file unless forced (:func:`write_file`)."""
from __future__ import annotations

import errno
import os
import stat
import tempfile
from typing import List, Optional, Tuple

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


def write_program(program: CsrProgram, path: str, newline: str = "\r\n", encoding: str = "ascii",
                  force: bool = False) -> None:
    """Write ``program`` to ``path`` with :func:`write_file` (atomic replacement of a regular file,
    keeping its mode; anything else refused unless ``force``)."""
    write_file(program_bytes(program, newline, encoding), path, force)


def write_file(data: bytes, path: str, force: bool = False) -> None:
    """Write ``data`` to ``path`` so that a failed write never leaves half a file and nothing but a
    regular file is ever replaced:

    - nothing there: a new regular file (mode 0666 minus the umask, like any new file);
    - a regular file: replaced by a temporary file of the same directory, given the old file's
      permission bits (and owner and group, where allowed) and then renamed over it; a file we may
      not write is refused, as the shell would;
    - anything else -- a symbolic link, a FIFO, a device, a socket, a directory -- is refused
      (CsrError, field "output") unless ``force``. With ``force`` a symbolic link is followed (its
      target written as above), a FIFO or a device is written in place (opened without creating or
      truncating; a FIFO without a reader is an error, not a hang); a directory is always refused.

    OSError for what the system refuses (no such directory, permission denied, disk full)."""
    st = _lstat(path)
    if st is not None and not stat.S_ISREG(st.st_mode):
        kind = _kind(st.st_mode)
        if stat.S_ISDIR(st.st_mode):
            raise CsrError("is a directory", 0, "output", path)
        if not force:
            raise CsrError("exists and is %s, not a regular file: refused (--force writes %s)"
                           % (kind, "through the link" if stat.S_ISLNK(st.st_mode) else "into it"),
                           0, "output", path)
        if stat.S_ISLNK(st.st_mode):
            target = os.path.realpath(path)
            target_st = _lstat(target)
            if target_st is not None and stat.S_ISLNK(target_st.st_mode):
                raise CsrError("is a symbolic link that does not resolve (a loop?)", 0, "output", path)
            write_file(data, target, force=True)
            return
        _write_in_place(data, path, kind)
        return
    _replace(data, path, st)


def _lstat(path: str) -> Optional[os.stat_result]:
    try:
        return os.lstat(path)
    except FileNotFoundError:
        return None


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a directory")):
        if test(mode):
            return name
    return "not a regular file"


def _write_in_place(data: bytes, path: str, kind: str) -> None:
    """--force on a FIFO or a device: write into it, creating and truncating nothing."""
    fifo = kind == "a FIFO"
    flags = os.O_WRONLY | getattr(os, "O_NOCTTY", 0) | (os.O_NONBLOCK if fifo else 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        if fifo and exc.errno == errno.ENXIO:
            raise CsrError("is a FIFO that nobody reads", 0, "output", path) from None
        raise
    try:
        if stat.S_ISREG(os.fstat(fd).st_mode):       # replaced by a regular file since the check
            raise CsrError("changed while being written (now a regular file); nothing written", 0, "output", path)
        if fifo:
            os.set_blocking(fd, True)
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
    finally:
        os.close(fd)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _replace(data: bytes, path: str, old: Optional[os.stat_result]) -> None:
    if old is not None and not os.access(path, os.W_OK):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), path)
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".csr-", dir=directory)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        if old is None:
            mode = 0o666 & ~_umask()
        else:
            mode = stat.S_IMODE(old.st_mode)
            if (old.st_uid, old.st_gid) != (os.getuid(), os.getgid()):
                try:
                    os.chown(tmp, old.st_uid, old.st_gid)    # before chmod: chown clears set-id bits
                except OSError:
                    pass                                     # not ours to give away: keep our own
        os.chmod(tmp, mode)
        now = _lstat(path)             # never rename over something that is not a regular file
        if now is not None and not stat.S_ISREG(now.st_mode):
            raise CsrError("became %s while being written: refused" % _kind(now.st_mode), 0, "output", path)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
