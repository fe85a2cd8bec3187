#!/usr/bin/python3
"""Run one systemd service unit the way systemd would, on a machine without systemd (tests).

  python3 test/_unit_supervisor.py UNIT_FILE --journal FILE

It reads the unit file and runs its ExecStart= exactly (split as systemd splits it), in the
environment systemd gives a service -- not the caller's: systemd's PATH, the User='s HOME, USER,
LOGNAME and SHELL, and the EnvironmentFile='s variables --, as that User= (or the current user when
it is that one), with LimitRTPRIO= as its rtprio limit, its output into the journal file. When the
main process ends it applies the unit's own rules: the rest of the service's processes get
KillSignal=, SIGKILL after TimeoutStopSec= (KillMode=control-group; a cgroup is stood for by this
process being the sub-reaper of everything the service starts), then, as Restart= says for the way
it ended, a new start after RestartSec=. SIGTERM to this process stops the service the same way
(systemctl stop) and ends it.

It tells what happens on stdout, one line each, flushed:
  started PID            the main process runs
  ended PID HOW          the main process ended: "status N" or "signal NAME"
  cleaned N              N leftover processes of the service were stopped
  restart SECONDS        Restart= allows a new start: after this delay
  no-restart             Restart= does not: the supervisor ends
"""
import ctypes
import os
import pwd
import resource
import shlex
import signal
import sys
import time

PR_SET_CHILD_SUBREAPER = 36
SYSTEMD_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
RESTART_RULES = {                   # Restart= value: does a main process that ended this way restart
    "no": lambda clean, sig: False,
    "always": lambda clean, sig: True,
    "on-success": lambda clean, sig: clean,
    "on-failure": lambda clean, sig: not clean,
    "on-abnormal": lambda clean, sig: sig is not None and sig not in (signal.SIGHUP, signal.SIGINT,
                                                                       signal.SIGTERM, signal.SIGPIPE),
}


def parse_unit(path):
    """{section: {key: [values in order]}} of a unit file (comments, blank lines, continuations)."""
    sections, section, pending = {}, None, ""
    with open(path) as f:
        for raw in f:
            line = pending + raw.rstrip("\n")
            pending = ""
            if line.endswith("\\"):
                pending = line[:-1] + " "
                continue
            stripped = line.strip()
            if not stripped or stripped[0] in "#;":
                continue
            if stripped.startswith("[") and stripped.endswith("]"):
                section = sections.setdefault(stripped[1:-1], {})
                continue
            if section is None or "=" not in stripped:
                raise ValueError("%s: not a unit file line: %r" % (path, line))
            key, value = stripped.split("=", 1)
            section.setdefault(key.strip(), []).append(value.strip())
    return sections


def seconds(value):
    """A systemd time span of this unit ("2", "2s", "500ms", "1min")."""
    for suffix, factor in (("ms", 0.001), ("min", 60.0), ("s", 1.0)):
        if value.endswith(suffix):
            return float(value[:-len(suffix)]) * factor
    return float(value)


def environment_file(path):
    env = {}
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith(("#", ";")):
                key, value = line.split("=", 1)
                env[key.strip()] = value.strip().strip('"')
    return env


class Service:
    def __init__(self, unit_path, journal):
        service = parse_unit(unit_path)["Service"]
        self.one = lambda key, default=None: service.get(key, [default])[-1]
        self.argv = shlex.split(self.one("ExecStart"))
        self.restart = self.one("Restart", "no")
        if self.restart not in RESTART_RULES:
            raise ValueError("Restart=%s: this supervisor knows %s" % (self.restart, ", ".join(RESTART_RULES)))
        self.restart_sec = seconds(self.one("RestartSec", "0.1"))
        self.kill_signal = getattr(signal, self.one("KillSignal", "SIGTERM"))
        self.stop_timeout = seconds(self.one("TimeoutStopSec", "90"))
        self.rtprio = self.one("LimitRTPRIO")
        user = pwd.getpwnam(self.one("User", "root"))
        if user.pw_uid != os.getuid() and os.getuid() != 0:
            raise ValueError("User=%s: only root can run a service as another user" % user.pw_name)
        self.user = user
        self.env = {"PATH": SYSTEMD_PATH, "HOME": user.pw_dir, "USER": user.pw_name, "LOGNAME": user.pw_name,
                    "SHELL": user.pw_shell, "LANG": "C.UTF-8"}
        for assignment in service.get("Environment", []):
            for word in shlex.split(assignment):
                key, value = word.split("=", 1)
                self.env[key] = value
        for path in service.get("EnvironmentFile", []):
            self.env.update(environment_file(path.lstrip("-")))
        self.journal = journal
        self.main = None
        self.stopping = False

    def start(self):
        out = os.open(self.journal, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        pid = os.fork()
        if pid == 0:                                          # the service's main process
            try:
                os.setsid()
                if self.rtprio is not None:
                    try:
                        resource.setrlimit(resource.RLIMIT_RTPRIO, (int(self.rtprio), int(self.rtprio)))
                    except (ValueError, OSError) as exc:      # a container without CAP_SYS_RESOURCE
                        os.write(out, ("supervisor: LimitRTPRIO=%s not applied here (%s): the bus process "
                                       "will say it runs at normal scheduling\n" % (self.rtprio, exc)).encode())
                if self.user.pw_uid != os.getuid():
                    os.setgroups([])
                    os.setgid(self.user.pw_gid)
                    os.setuid(self.user.pw_uid)
                os.chdir("/")                                 # systemd's working directory by default
                null = os.open(os.devnull, os.O_RDONLY)
                os.dup2(null, 0)
                os.dup2(out, 1)
                os.dup2(out, 2)
                os.execve(self.argv[0], self.argv, self.env)
            except BaseException as exc:                   # said in the journal, as systemd would
                os.write(out, ("supervisor: the service did not start: %r\n" % (exc,)).encode())
            finally:
                os._exit(127)
        os.close(out)
        self.main = pid
        say("started %d" % pid)

    def leftovers(self):
        """Every process below this one (the service's: this process is their sub-reaper)."""
        found, todo = [], [os.getpid()]
        while todo:
            pid = todo.pop()
            try:
                for task in os.listdir("/proc/%d/task" % pid):
                    with open("/proc/%d/task/%s/children" % (pid, task)) as f:
                        todo += [int(c) for c in f.read().split()]
            except OSError:
                continue
            if pid != os.getpid():
                found.append(pid)
        return found

    def reap(self):
        """Reap every ended child; the main process's wait status when it was among them."""
        status = None
        while True:
            try:
                pid, st = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                return status
            if pid == 0:
                return status
            if pid == self.main:
                status = st

    def clean(self):
        """KillMode=control-group: KillSignal= to what is left, SIGKILL after TimeoutStopSec=."""
        left = self.leftovers()
        for pid in left:
            with _quiet():
                os.kill(pid, self.kill_signal)
        end = time.monotonic() + self.stop_timeout
        while self.leftovers() and time.monotonic() < end:
            self.reap()
            time.sleep(0.05)
        for pid in self.leftovers():
            with _quiet():
                os.kill(pid, signal.SIGKILL)
        while self.leftovers():
            self.reap()
            time.sleep(0.02)
        self.reap()
        return len(left)

    def run(self):
        signal.signal(signal.SIGTERM, lambda *_: setattr(self, "stopping", True))
        self.start()
        while True:
            status = self.reap()
            if self.stopping:
                if status is None and self.main is not None:
                    with _quiet():
                        os.kill(self.main, self.kill_signal)
                say("cleaned %d" % self.clean())
                return 0
            if status is None:
                time.sleep(0.05)
                continue
            if os.WIFSIGNALED(status):
                sig = os.WTERMSIG(status)
                say("ended %d signal %s" % (self.main, signal.Signals(sig).name))
                clean_exit = sig in (signal.SIGHUP, signal.SIGINT, signal.SIGTERM, signal.SIGPIPE)
            else:
                sig = None
                say("ended %d status %d" % (self.main, os.WEXITSTATUS(status)))
                clean_exit = os.WEXITSTATUS(status) == 0
            self.main = None
            say("cleaned %d" % self.clean())
            if not RESTART_RULES[self.restart](clean_exit, sig):
                say("no-restart")
                return 0
            say("restart %g" % self.restart_sec)
            end = time.monotonic() + self.restart_sec
            while time.monotonic() < end and not self.stopping:
                time.sleep(0.05)
            if self.stopping:
                return 0
            self.start()


class _quiet:
    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        return kind is not None and issubclass(kind, ProcessLookupError)


def say(words):
    sys.stdout.write(words + "\n")
    sys.stdout.flush()


def main(argv):
    if len(argv) != 3 or argv[1] != "--journal":
        print(__doc__.strip(), file=sys.stderr)
        return 2
    if ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        print("prctl(PR_SET_CHILD_SUBREAPER) refused", file=sys.stderr)
        return 2
    return Service(argv[0], argv[2]).run()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
