"""The repository checks' two groups (scripts/test runs them apart): the ones that only compute
(static checks, launch files parsed, generators checked) and the ones that start nodes, the
scripts or the benchmarks and wait on the wall clock. `pytest --lane computation|realtime` selects
one group; without --lane every module runs. A new module that starts processes and waits on them
belongs in REALTIME."""

REALTIME = {
    "test_scripts.py",             # scripts/run with the driver and the virtual controller, scripts/setup
    "test_benches.py",             # the benchmarks' smoke runs (latency, bus cycles, a roscore of its own)
    "test_interface_node.py",      # the node as a process with a roscore
    "test_cell_service.py",        # the cell PC's units (install-cell) run, killed and restarted, against the virtual G2
}
LANES = ("computation", "realtime")


def pytest_addoption(parser):
    parser.addoption("--lane", choices=LANES, default=None,
                     help="run only this group of test modules (scripts/test runs them apart)")


def pytest_ignore_collect(collection_path, config):
    lane = config.getoption("--lane")
    if lane is None or collection_path.suffix != ".py" or not collection_path.name.startswith("test_"):
        return None
    return True if ("realtime" if collection_path.name in REALTIME else "computation") != lane else None
