"""scripts/junit_summary: the counts, the exit code, and a failure's message in full enough to act on
(its first line, then its last lines: a rostest's assertion often ends with the output that explains
it, and the CI log is all a fresh-clone run leaves)."""
import os
import subprocess
import sys

SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts", "junit_summary")


def run(tmp_path, xml):
    (tmp_path / "r.xml").write_text(xml)
    done = subprocess.run([sys.executable, SCRIPT, str(tmp_path)], stdout=subprocess.PIPE, universal_newlines=True)
    return done.returncode, done.stdout


def test_a_failure_shows_its_first_line_and_its_last_lines(tmp_path):
    body = "&#10;".join(["1 != 0 : the command failed"] + ["line %d" % i for i in range(100)])
    code, out = run(tmp_path, '<testsuite><testcase classname="A" name="t1"><failure message="%s"/></testcase>'
                              '<testcase classname="A" name="t2"/></testsuite>' % body)
    assert code == 1
    assert "FAILED A.t1: 1 != 0 : the command failed" in out
    assert "    line 99" in out and "    line 70" in out and "line 69\n" not in out
    assert "[... 70 lines ...]" in out
    assert out.rstrip().endswith("summary: 1 passed, 1 failed, 0 skipped")


def test_all_passed_is_exit_0_and_nothing_run_is_not(tmp_path):
    code, out = run(tmp_path, '<testsuite><testcase classname="A" name="t"/></testsuite>')
    assert code == 0 and "summary: 1 passed, 0 failed, 0 skipped" in out
    code, _ = run(tmp_path, '<testsuite/>')
    assert code == 1
