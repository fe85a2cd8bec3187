"""csr_export and hostile files (issue 15, defect 6): bounded inputs (size, YAML aliases, nesting),
short quotes of values in messages, and an -o that replaces only regular files, atomically,
keeping their mode. Plain asserts, no pytest fixtures; nothing here measures time."""
from __future__ import annotations

import contextlib
import io
import os
import resource
import stat
import subprocess
import sys
import tempfile

import pytest

from vr_driver import csr
from vr_driver.csr import inputs
from vr_driver.errors import CsrError

HERE = os.path.dirname(os.path.abspath(__file__))
PKG = os.path.dirname(HERE)
REPO = os.path.dirname(PKG)
EXAMPLES = os.path.join(PKG, "examples")
WAYPOINTS = os.path.join(EXAMPLES, "waypoints.yaml")
PYTHONPATH = os.pathsep.join(os.path.join(REPO, p, "src") for p in ("vr_driver", "panasonic_vr006l_support",
                                                                    "pyprofibus_vendor"))
POSE = "waypoints:\n  - pose: [1120, 0, 725, 0, 45, 0]\n"


def run_main(*argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = csr.main(list(argv))
    return code, out.getvalue(), err.getvalue()


def write(folder, name, text):
    path = os.path.join(folder, name)
    with open(path, "w") as f:
        f.write(text)
    return path


def read_bytes(path):
    with open(path, "rb") as f:
        return f.read()


def laughs(levels, width=9):
    """A "billion laughs" tree under program: date: -- level k is a list of ``width`` aliases of
    level k-1, so the last one expands to width**levels strings, from a few hundred bytes."""
    rows = ["  - &a0 [%s]" % ", ".join(["lol"] * width)]
    rows += ["  - &a%d [%s]" % (k, ", ".join(["*a%d" % (k - 1)] * width)) for k in range(1, levels)]
    return "program:\n  date:\n" + "\n".join("  " + r for r in rows) + "\n" + POSE


def _limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))   # the old code ate all memory


# ==================================================================================== bounded input

def test_billion_laughs_is_refused_with_a_clear_error_in_a_bounded_process():
    """The issue's file: a nine-level alias tree under program: date:. It used to run 40 s and die
    with MemoryError; now it is one line naming the limit. The subprocess runs with 2 GB of address
    space and a 120 s safety stop, so a regression fails instead of taking the machine down."""
    with tempfile.TemporaryDirectory() as tmp:
        path = write(tmp, "laughs.yaml", laughs(9))
        assert os.path.getsize(path) < 600
        env = dict(os.environ, PYTHONPATH=PYTHONPATH)
        proc = subprocess.run([sys.executable, "-m", "vr_driver.csr", path, "-o", os.path.join(tmp, "o.csr")],
                              capture_output=True, text=True, timeout=120, env=env, preexec_fn=_limit_memory)
        assert proc.returncode == 2, proc.stderr[-500:]
        assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr[-500:]
        assert "laughs.yaml:" in proc.stderr and "aliases expand to more than" in proc.stderr
        assert not os.path.exists(os.path.join(tmp, "o.csr"))


def test_an_expansion_below_the_limit_is_quoted_short():
    """Six levels (531 441 strings) pass the expansion limit; the refused date is quoted by a short
    prefix (one level less than the issue's file wrote a 140 MB message)."""
    code, _, err = run_main_on(laughs(6))
    assert code == 2 and err.count("\n") == 1
    assert "program date:" in err and "is not a date" in err
    assert len(err) < 300, len(err)


def run_main_on(text, name="wp.yaml", *argv):
    with tempfile.TemporaryDirectory() as tmp:
        return run_main(write(tmp, name, text), "-o", os.path.join(tmp, "o.csr"), *argv)


@pytest.mark.parametrize("text, words", [
    ("x: &x 1\nprogram:\n  comment: [" + ", ".join(["*x"] * 1001) + "]\n" + POSE, "more than 1000 YAML aliases"),
    ("waypoints: " + "[" * 5000 + "]" * 5000 + "\n", "nested deeper than 32 levels"),
    ("program:\n  date: &r [1, *r]\n" + POSE, "recursive YAML alias"),
], ids=["aliases", "depth", "recursive"])
def test_yaml_aliases_and_depth_are_bounded(text, words):
    code, _, err = run_main_on(text)
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err and words in err, err


def test_an_alias_chain_that_nests_too_deep_is_refused_before_it_is_built():
    """Each level 20 deep in the text, aliases of the level before: the built value would nest
    20 * 10 levels (construction recurses that deep)."""
    rows = ["x0: &x0 1"]
    rows += ["x%d: &x%d %s*x%d%s" % (k, k, "[" * 20, k - 1, "]" * 20) for k in range(1, 11)]
    err = raises(CsrError, csr.parse_waypoints, "\n".join(rows) + "\n", "deep.yaml")
    assert "nest deeper than 32 levels" in str(err) and err.source == "deep.yaml" and err.line > 0


def test_ordinary_anchors_still_work():
    text = "waypoints:\n  - pose: &home [1120, 0, 725, 0, 45, 0]\n  - joints_deg: [0, 0, 0, 0, 0, 0]\n  - pose: *home\n"
    wfile = csr.parse_waypoints(text, "wp.yaml")
    assert wfile.waypoints[2].pose == wfile.waypoints[0].pose and wfile.waypoints[2].line == 4


def test_input_files_are_bounded_in_size():
    with tempfile.TemporaryDirectory() as tmp:
        big = write(tmp, "big.yaml", POSE + "#" * inputs.MAX_INPUT_BYTES + "\n")
        code, _, err = run_main(big, "-o", os.path.join(tmp, "o.csr"))
        assert code == 2 and err.count("\n") == 1 and "big.yaml: input: larger than" in err, err
        code, _, err = run_main("--from-csr", big)
        assert code == 2 and "big.yaml: file: larger than" in err, err
        code, _, err = run_main(WAYPOINTS, "--driver-config", big, "-o", os.path.join(tmp, "o.csr"))
        assert code == 2 and "big.yaml: --driver-config: larger than" in err, err


def test_the_driver_config_goes_through_the_bounded_loader():
    with tempfile.TemporaryDirectory() as tmp:
        bad = write(tmp, "driver.yaml", laughs(9).replace("program:", "workspace:"))
        code, _, err = run_main(WAYPOINTS, "--driver-config", bad, "-o", os.path.join(tmp, "o.csr"))
    assert code == 2 and "--driver-config: the YAML aliases expand" in err, err


# (the long lists: 10 000 items, 20 000 to 100 000 characters against a message's 300; 100 000 items
# cost 7 s each in the YAML parser and showed nothing more)
@pytest.mark.parametrize("text, field", [
    ("program:\n  comment: " + "x" * 100000 + "\n" + POSE, "program Comment"),
    ("program:\n  creator: [" + ", ".join(["abcdefgh"] * 10000) + "]\n" + POSE, "program Creator"),
    ("program:\n  comment: " + "9" * 5000 + "\n" + POSE, "input: a value cannot be read"),
    ("waypoints:\n  - pose: [" + ", ".join(["1"] * 10000) + "]\n", "waypoint 1 pose"),
    ("waypoints:\n  - {" + "k" * 1000 + ": 1, pose: [1120, 0, 725, 0, 45, 0]}\n", "waypoint 1"),
    ("waypoints:\n  - pose: [1120, 0, 725, 0, 45, 0]\n    move: " + "lin" * 50000 + "\n", "waypoint 1 move"),
], ids=["long-comment", "long-list", "long-int", "long-pose", "long-key", "long-move"])
def test_messages_quote_a_short_prefix_of_a_value(text, field):
    code, _, err = run_main_on(text)
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err[:500]
    assert field in err and len(err) < 300, err[:500]


def test_show_is_short_for_any_value():
    assert csr.fields.show("abc") == "'abc'"
    assert csr.fields.show([1, 2]) == "[1, 2]"
    huge = [["x" * 1000] * 1000] * 1000
    for value in ("y" * 10 ** 6, huge, {"k" * 1000: huge}, 7 ** 100000, b"\0" * 10 ** 5):
        text = csr.fields.show(value)
        assert len(text) <= csr.fields.SHOW_MAX and text.endswith(("...", ">")), text


def raises(exc_type, func, *args, **kwargs):
    with pytest.raises(exc_type) as info:
        func(*args, **kwargs)
    return info.value


# ========================================================================================== output

def export_to(out, *argv):
    return run_main(WAYPOINTS, "-o", out, *argv)


def fresh_export():
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "ref.csr")
        code, _, err = export_to(out)
        assert code == 0, err
        return read_bytes(out)


def test_a_symlink_output_is_refused_unless_forced_then_followed():
    with tempfile.TemporaryDirectory() as tmp:
        target = write(tmp, "target.csr", "keep me\n")
        link = os.path.join(tmp, "link.csr")
        os.symlink(target, link)
        code, _, err = export_to(link)
        assert code == 2 and err.count("\n") == 1 and "symbolic link" in err and "--force" in err, err
        assert os.path.islink(link) and read_bytes(target) == b"keep me\n"
        assert sorted(os.listdir(tmp)) == ["link.csr", "target.csr"]          # no temporary left
        code, _, err = export_to(link, "--force")
        assert code == 0, err
        assert os.path.islink(link) and read_bytes(target) == fresh_export()


def test_a_fifo_output_is_refused_unless_forced_then_written_in_place():
    with tempfile.TemporaryDirectory() as tmp:
        fifo = os.path.join(tmp, "out.fifo")
        os.mkfifo(fifo)
        code, _, err = export_to(fifo)
        assert code == 2 and "is a FIFO, not a regular file: refused" in err, err
        assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
        code, _, err = export_to(fifo, "--force")                           # nobody reads: an error, no hang
        assert code == 2 and "FIFO that nobody reads" in err, err
        reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
        try:
            code, _, err = export_to(fifo, "--force")
            assert code == 0, err
            data = b""
            while True:
                try:
                    chunk = os.read(reader, 65536)
                except BlockingIOError:
                    break
                if not chunk:
                    break
                data += chunk
        finally:
            os.close(reader)
        assert data == fresh_export()
        assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_directory_output_is_refused_even_when_forced():
    with tempfile.TemporaryDirectory() as tmp:
        for extra in ((), ("--force",)):
            code, _, err = export_to(tmp, *extra)
            assert code == 2 and "is a directory" in err.lower(), err
        assert os.listdir(tmp) == []


def test_an_existing_file_keeps_its_mode_and_a_new_one_follows_the_umask():
    with tempfile.TemporaryDirectory() as tmp:
        out = write(tmp, "o.csr", "old\n")
        os.chmod(out, 0o640)
        code, _, err = export_to(out)
        assert code == 0, err
        assert stat.S_IMODE(os.stat(out).st_mode) == 0o640 and read_bytes(out) == fresh_export()
        os.chmod(out, 0o604)
        code, _, err = export_to(out)
        assert code == 0 and stat.S_IMODE(os.stat(out).st_mode) == 0o604, err
        old_mask = os.umask(0o027)
        try:
            new = os.path.join(tmp, "new.csr")
            code, _, err = export_to(new)
        finally:
            os.umask(old_mask)
        assert code == 0 and stat.S_IMODE(os.stat(new).st_mode) == 0o640, err
        assert sorted(os.listdir(tmp)) == ["new.csr", "o.csr"]


def test_write_program_refuses_a_symlink_and_keeps_the_mode():
    program = csr.parse_program(read_bytes(os.path.join(EXAMPLES, "waypoints.csr")).decode())
    with tempfile.TemporaryDirectory() as tmp:
        out = write(tmp, "p.csr", "")
        os.chmod(out, 0o600)
        csr.write_program(program, out)
        assert stat.S_IMODE(os.stat(out).st_mode) == 0o600
        assert read_bytes(out) == csr.program_bytes(program)
        link = os.path.join(tmp, "l.csr")
        os.symlink(out, link)
        err = raises(CsrError, csr.write_program, program, link)
        assert err.field == "output" and "symbolic link" in err.reason


def test_dash_o_dash_writes_to_standard_output():
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PYTHONPATH=PYTHONPATH)
        for argv in ([WAYPOINTS, "-o", "-"], ["--from-csr", os.path.join(EXAMPLES, "waypoints.csr"), "-o", "-"]):
            proc = subprocess.run([sys.executable, "-m", "vr_driver.csr"] + argv, capture_output=True,
                                  timeout=60, env=env, cwd=tmp)
            assert proc.returncode == 0, proc.stderr
            assert proc.stdout.splitlines() == fresh_export().splitlines() and proc.stderr == b""
            assert os.listdir(tmp) == []                                    # no file named "-"
