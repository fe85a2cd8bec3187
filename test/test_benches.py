"""Smoke runs of the benchmarks: they run to the end and print their figure lines (timings unchecked)."""
import os
import re
import subprocess
import unittest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NUM = r"[0-9]+(?:\.[0-9]+)?"


def bench(name, *args, timeout=300):
    """``bench/NAME.py ARGS`` in the workspace's environment, as scripts/bench runs it after its
    set-up (scripts/test has set up the workspace and the test peers; a set-up per benchmark took
    8 s each). FuzzBenchTest goes through scripts/bench itself."""
    return subprocess.run([os.path.join(REPO, "scripts", "env"), "python3", os.path.join(REPO, "bench", name + ".py")]
                          + list(args), capture_output=True, text=True, timeout=timeout)


class BenchRun(unittest.TestCase):
    """Runs ``bench/BENCH.py --quick`` once for the class; ``line`` checks a figure line."""

    BENCH = ""
    TIMEOUT = 300

    @classmethod
    def setUpClass(cls):
        if not cls.BENCH:             # the base class itself has no tests
            raise unittest.SkipTest("base class")
        cls.res = bench(cls.BENCH, "--quick", timeout=cls.TIMEOUT)
        cls.out = cls.res.stdout

    def line(self, pattern):
        self.assertRegex(self.out, re.compile(pattern, re.M),
                         "missing line /%s/ in:\n%s\n%s" % (pattern, self.out, self.res.stderr[-3000:]))


class DpCycleBenchTest(BenchRun):
    BENCH = "dp_cycle"

    def test_exits_0(self):
        self.assertEqual(self.res.returncode, 0, self.out + self.res.stderr[-3000:])
        self.assertNotIn("FAILED", self.out)

    def test_every_variant_has_its_figures(self):
        """cycles/s, master CPU, server CPU and wall time per cycle; pyprofibus is there because
        scripts/bench sets up the test-peer venv."""
        for name in ("floor", "slave-only", "ours", "pyprofibus"):
            self.line(r"^%s\s+%s\s+%s\s+%s\s+%s\s+\S" % (re.escape(name), NUM, NUM, NUM, NUM))

    def test_ratios_100hz_wire_times_and_targets(self):
        for ratio in ("ours/floor cycles/s", "ours/slave-only cycles/s", "ours/pyprofibus cycles/s",
                      "ours/pyprofibus CPU per cycle"):
            self.line(r"^ratio %s:\s+%s$" % (re.escape(ratio), NUM))
        self.line(r"^100 Hz: DpMaster\.run\(period=0\.01\) for %s s: [0-9]+ cycles .* master %s %% of one core"
                  % (NUM, NUM))
        self.line(r"^100 Hz floor: .* %s %% of one core" % NUM)
        for baud in ("19.2k", "187.5k", "1.5M"):
            self.line(r"^wire %s\s+TSDR\s+[0-9]+\.\.\s*[0-9]+ bit:\s+%s \.\.\s+%s us" % (re.escape(baud), NUM, NUM))
        targets = re.findall(r"^(PASS|MISS) ", self.out, re.M)
        self.assertEqual(len(targets), 4, self.out)


class DpLineBenchTest(BenchRun):
    """bench/dp_line.py --quick: our master with 1, 2 and 4 stations on the paced virtual line at 19.2 and
    187.5 kbit/s; a figure line per configuration, with every station exchanged every cycle or the
    stations short of exchanges and the losses counted (the line is paced in processes of its own:
    on a loaded machine it misses slot times, 1 to 3 losses in 0.5 s beside other tests)."""
    BENCH = "dp_line"

    def test_exits_0_with_a_line_per_configuration(self):
        self.assertEqual(self.res.returncode, 0, self.out + self.res.stderr[-3000:])
        self.assertNotIn("FAILED", self.out)
        notes = r"(every station every cycle|[0-9]+ station\(s\) short of exchanges, [0-9]+ loss\(es\))"
        for baud in ("19200", "187500"):
            for n in ("1", "2", "4"):
                self.line(r"^%s\s+%s\s+%s\s+%s\s+%s\s+%s$" % (n, baud, NUM, NUM, NUM, notes))


class DriverLatencyBenchTest(BenchRun):
    """bench/driver_latency.py --quick: its own roscore + driver.launch (sim), 3 goals, 2 e-stops, a 2 s
    idle window (about 15 s); every figure line is there, no timing is checked."""

    BENCH = "driver_latency"
    TIMEOUT = 180

    def test_exits_0(self):
        self.assertEqual(self.res.returncode, 0, self.out + self.res.stderr[-3000:])
        self.assertNotIn("FAILED", self.out)
        self.assertNotIn("had to kill", self.out)

    def test_sections_have_their_figures(self):
        row = r"\s+%s\s+%s\s+%s\s+[0-9]+$" % (NUM, NUM, NUM)
        for label in ("send_goal -> controller BUSY (execution-log start_time)",
                      'send_goal -> client: first feedback phase "moving"',
                      "send_goal -> client: first robot_status in_motion TRUE",
                      "press: controller log -> client: e_stopped TRUE",
                      "press: service return -> client: e_stopped TRUE",
                      "release: controller log -> client: e_stopped FALSE"):
            self.line(r"^%s%s" % (re.escape(label), row))
        for topic in ("joint_states", "robot_status"):
            self.line(r"^%s\s+[0-9]+\s+%s\s+%s\s+%s" % (topic, NUM, NUM, NUM))
        self.line(r"^CPU /interface\s+%s %% of one core \(pid [0-9]+, /proc/[0-9]+/stat" % NUM)
        self.line(r"^clock check: .* for [0-9]+ of [0-9]+ goals")

    def test_summary_table(self):
        self.line(r"^=== summary: median / p95 / max ms")
        cell = r"%s / %s / %s \([0-9]+\)" % (NUM, NUM, NUM)
        for label in ("goal -> controller BUSY", "goal -> feedback moving", "goal -> robot_status in_motion",
                      "e-stop press (ctrl log) -> robot_status", "e-stop press (svc return) -> robot_status",
                      "e-stop release (ctrl log) -> robot_status"):
            self.line(r"^%s\s+%s$" % (re.escape(label), cell))
        for topic in ("joint_states", "robot_status"):
            self.line(r"^%s rate, jitter sd, max gap \(ms\)\s+%s Hz, sd %s, max gap %s$" % (topic, NUM, NUM, NUM))
        self.line(r"^interface CPU idle \(%% of one core\)\s+%s %%$" % NUM)
        self.line(r"^python .* wall time %s s$" % NUM)


class FuzzBenchTest(unittest.TestCase):
    """bench/fuzz.py in small: the deframer, the slave engine and the master take 20 000 random and
    mutated telegrams each with nothing but typed errors and no data from a damaged telegram. Through
    scripts/bench, as a person runs it (its set-up, its header line)."""

    def test_fuzz_passes(self):
        res = subprocess.run([os.path.join(REPO, "scripts", "bench"), "fuzz", "--", "--frames", "20000"],
                             capture_output=True, text=True, timeout=300)
        self.assertEqual(res.returncode, 0, res.stdout + res.stderr[-3000:])
        self.assertIn("=== bench/fuzz.py --frames 20000", res.stdout)
        for target in ("deframer", "slave", "master"):
            self.assertRegex(res.stdout, r"--- %s: [0-9]+ telegrams in .* violations 0" % target)
        self.assertRegex(res.stdout, r"outputs delivered\s+[1-9]")       # it got to Data_Exchange
        self.assertRegex(res.stdout, r"inputs delivered\s+[1-9]")
        self.assertIn("RESULT: PASS (violations 0)", res.stdout)


class CollisionBenchTest(BenchRun):
    """bench/collision.py --quick: the time per call of each collision query beside FK, and the
    ratios (skipped with a line naming the package where pinocchio / coal are missing)."""
    BENCH = "collision"

    def test_figures(self):
        self.assertEqual(self.res.returncode, 0, self.out + self.res.stderr[-3000:])
        if "collision benchmark skipped:" in self.out:
            self.skipTest(self.out.strip().splitlines()[-1])
        for query in ("pin FK", "KDL FK", "in_collision", "in_collision free", "in_collision hit", "min_distance",
                      "contacts"):
            self.line(r"^%s\s+%s$" % (re.escape(query), NUM))
        self.line(r"^ratio in_collision / pin FK: %s$" % NUM)
        self.line(r"^ratio in_collision / KDL FK: %s$" % NUM)
        self.line(r"^free [0-9]+, colliding [0-9]+ \(%s %% free\)$" % NUM)


class PlanningBenchTest(BenchRun):
    """bench/planning.py --quick: 10 chained queries in the example cell, planned, re-checked and
    executed on the in-memory driver rig (skipped with a line naming the package where OMPL,
    TOPP-RA, pinocchio or coal are missing)."""
    BENCH = "planning"

    def test_figures(self):
        self.assertEqual(self.res.returncode, 0, self.out + self.res.stderr[-3000:])
        if "planning benchmark skipped:" in self.out:
            self.skipTest(self.out.strip().splitlines()[-1])
        self.line(r"^success: [0-9]+ / 10 \(%s %%\); joint goals [0-9]+ / 5, pose goals [0-9]+ / 5$" % NUM)
        self.line(r"^planning time \[ms\]: median %s  p95 %s  max %s " % (NUM, NUM, NUM))
        self.line(r"^path duration \[s\]: median %s  p95 %s  max %s$" % (NUM, NUM, NUM))
        self.line(r"^planned samples and chord points in collision: 0; inside the padding: 0$")
        self.line(r"^execution: [0-9]+ / [0-9]+ plans succeeded on the rig; [1-9][0-9]* joint samples checked .*, "
                  r"0 in collision$")
        self.line(r"^(PASS|MISS) success >= 99 %%: %s %%$" % NUM)
        self.line(r"^(PASS|MISS) median <= 100 ms: %s ms$" % NUM)


class BusHealthBenchTest(BenchRun):
    """bench/bus_health.py in small: 19.2 kbit/s, idle and two CPU hogs, before and after (1 s windows:
    the hogs take both cores from the tests running beside this one); a table row per case with the
    card's figures, and the verdict line (the gaps themselves unchecked)."""
    BENCH = "bus_health"
    ARGS = ("--quick", "--window", "1", "--bauds", "19200", "--loads", "idle,hog")

    @classmethod
    def setUpClass(cls):
        cls.res = subprocess.run([os.path.join(REPO, "scripts", "bench"), cls.BENCH, "--"] + list(cls.ARGS),
                                 capture_output=True, text=True, timeout=cls.TIMEOUT)
        cls.out = cls.res.stdout

    def test_exits_0(self):
        self.assertEqual(self.res.returncode, 0, self.out + self.res.stderr[-3000:])
        self.assertNotIn("FAILED", self.out)

    def test_a_row_per_case_and_the_verdict(self):
        for load in ("idle", "hog"):
            for design in ("before", "after"):
                # bit/s, load, design, run [s], DX cycles, max, p99.9, watchdog expiries, losses card / driver,
                # the driver's longest bus-loop iteration: measured, never 0.0 (it read 0.0 when the
                # bench timed a method the bus thread no longer called)
                self.line(r"^19200\s+%s\s+%s\s+%s\s+[1-9][0-9]*\s+%s\s+%s\s+[0-9]+\s+[0-9]+ / [0-9]+\s+"
                          r"(?!0\.0\s)[0-9]+\.[0-9]\s" % (load, design, NUM, NUM, NUM))
        # the designs differ: the bus in the driver's own process, then in a process of its own
        self.line(r"^19200\s+idle\s+before\s.*in the driver's process$")
        self.line(r"^19200\s+idle\s+after\s.*process [0-9]+, (SCHED_FIFO|normal scheduling)")
        self.line(r"^(PASS|MISS) target \(after: 0 watchdog expiries, every gap < 150 ms\)")
        self.line(r"^python .* wall time %s s$" % NUM)
        self.line(r"^19200 bit/s hog\s+after\s*:.*; 2 busy loops for 1 s$")       # --window is kept by --quick


if __name__ == "__main__":
    unittest.main()
