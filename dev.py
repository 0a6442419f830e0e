#!/usr/bin/env python3
"""Set up and run landmark-companion from a fresh clone, with only Python >= 3.11 and git.

    python3 dev.py demo [ARGS...]   install (once) and run the main job: companion demo ARGS
    python3 dev.py test [ARGS...]   install (once) and run the whole test suite:
                                    ruff, mypy, then pytest (ARGS go to pytest; without
                                    ARGS the flights that need the machine to
                                    themselves fly first, then the other long real-time
                                    flights run beside the rest)
    python3 dev.py lock             regenerate requirements/*.lock (maintainers)

The environment is a virtualenv in .venv, installed from the hash-checked lock files in
requirements/ and reinstalled only when a lock file or pyproject.toml changes.  Standard
library only: this script runs before anything is installed.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import signal
import subprocess
import sys
import time
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
PY = BIN / ("python.exe" if os.name == "nt" else "python")
LOCKS = {"runtime": ROOT / "requirements" / "runtime.lock",
         "dev": ROOT / "requirements" / "dev.lock"}
#: Test tools installed without their declared dependencies (see the file's header).
TOOLS = ROOT / "requirements" / "tools.lock"
PYTEST_NO_TESTS = 5
#: The marker of the long real-time flights (conftest.py REALTIME) and where ``test`` writes
#: their pytest's output while the rest of the suite runs beside them (test-output/ is ignored
#: by git).
REALTIME = "realtime"
#: The marker of the flights that fly alone, before the others and the rest, with nothing
#: beside them (conftest.py ALONE): their bounds are on timing that a busy core breaks.
ALONE = "alone"
FLIGHTS_LOG = ROOT / "test-output" / "pytest-realtime.log"
#: How much lower the rest of the suite runs beside the flights (``nice``): on a 2-core
#: machine where the rest took 795 s, the strict square dropped 17 % of its frames beside
#: it and missed its 1 s gap on 1 to 3 of its 5 seeds (docs/testing.md, "CI's budget").
REST_NICE = 10
#: How long the flights get to end on SIGTERM before they are killed (an interrupted suite).
STOP_GRACE_S = 5.0
#: The optional features (pyproject.toml); the locks and so the dev environment hold them all.
EXTRAS = ("postgis", "dashboard", "mavsdk")


def say(text: str) -> None:
    print(f"[dev] {text}", flush=True)


def run(*cmd: str | Path, check: bool = True, nice: int = 0) -> int:
    """Run a command from the project root (``nice``: that much lower in the scheduler's
    priority); stop with its status when it fails."""
    def lower() -> None:
        os.nice(nice)

    result = subprocess.run([str(c) for c in cmd], cwd=ROOT, check=False,
                            preexec_fn=lower if nice > 0 else None)
    if check and result.returncode != 0:
        say(f"failed ({result.returncode}): {' '.join(str(c) for c in cmd)}")
        sys.exit(result.returncode)
    return result.returncode


def fingerprint(kind: str) -> str:
    digest = hashlib.sha256(kind.encode())
    for path in (LOCKS[kind], ROOT / "pyproject.toml", *([TOOLS] if kind == "dev" else [])):
        digest.update(path.read_bytes())
    return digest.hexdigest()


def ensure_env(kind: str) -> None:
    """Create .venv and install the locked dependencies of ``kind`` unless already done."""
    if sys.version_info < (3, 11):  # noqa: UP036 - runs before anything is checked
        sys.exit(f"[dev] Python >= 3.11 is needed, this is {sys.version.split()[0]}")
    stamp = VENV / f".installed-{kind}"
    want = fingerprint(kind)
    if PY.exists() and stamp.exists() and stamp.read_text() == want:
        return
    if not PY.exists():
        say(f"creating the virtual environment in {VENV.name}/")
        venv.EnvBuilder(with_pip=True).create(VENV)
    say(f"installing locked {kind} dependencies (first run takes a few minutes)")
    run(PY, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
        "--require-hashes", "-r", LOCKS[kind])
    if kind == "dev":
        run(PY, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
            "--require-hashes", "--no-deps", "-r", TOOLS)
    say("installing landmark-companion itself (editable)")
    run(PY, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
        "--no-deps", "-e", ".")
    for old in VENV.glob(".installed-*"):
        old.unlink()
    stamp.write_text(want)
    if kind == "dev":  # the dev lock includes every runtime package
        (VENV / ".installed-runtime").write_text(fingerprint("runtime"))


def cmd_demo(args: list[str]) -> int:
    ensure_env("runtime")
    return run(BIN / "companion", "demo", *args, check=False)


def cmd_test(args: list[str]) -> int:
    ensure_env("dev")
    say("ruff")
    run(PY, "-m", "ruff", "check", ".")
    say("mypy")
    run(PY, "-m", "mypy")
    if args or usable_cores() < 2:
        say("pytest")
        return pytest_status(run(PY, "-m", "pytest", *args, check=False))
    # a SIGTERM (a CI's timeout) unwinds like Ctrl-C, so that no flight is left running
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    return pytest_beside_flights()


def usable_cores() -> int:
    """The cores this process may run on (its affinity where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def pytest_status(status: int) -> int:
    """pytest's exit status, with "no tests collected" (5) a failure."""
    if status == PYTEST_NO_TESTS:
        say("pytest collected no tests: that is a failure here (wrong path or filter?)")
        return 1
    return status


def pytest_beside_flights() -> int:
    """The whole suite as three pytests: first the flights marked ``alone`` (conftest.py
    ALONE) with nothing beside them, in the foreground; then the other real-time flights
    (marker ``realtime``) in the background, writing to :data:`FLIGHTS_LOG`, while the rest
    runs in the foreground; then the flights' output, followed live until they end.
    The flights wait on the clock (~0.5 core each, one at a time): side by side the suite
    takes the longer of the two instead of their sum (docs/testing.md, "CI's budget").
    Every part runs whatever an earlier one did, and any failing fails the suite.
    Interrupted, the flights' process group is ended too (:func:`stop_group`)."""
    say(f"pytest: the flights that fly alone (-m \"{REALTIME} and {ALONE}\"), nothing beside")
    alone = run(PY, "-m", "pytest", "-m", f"{REALTIME} and {ALONE}", "-p", "no:cacheprovider",
                check=False)
    FLIGHTS_LOG.parent.mkdir(exist_ok=True)
    shown = FLIGHTS_LOG.relative_to(ROOT)
    beside = f"{REALTIME} and not {ALONE}"
    say(f"pytest: the other real-time flights (-m \"{beside}\") in the background, output in "
        f"{shown}")
    with FLIGHTS_LOG.open("w") as log:
        # a session of its own: the terminal's Ctrl-C reaches the rest only, and the flights
        # (pytest and every process it started) are stopped as one group below
        flights = subprocess.Popen(
            [str(PY), "-m", "pytest", "-m", beside, "-p", "no:cacheprovider"],
            cwd=ROOT, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            say(f"pytest: the rest (-m \"not {REALTIME}\")")
            # the flights are judged on their timing, the rest is not: it yields the cores
            rest = run(PY, "-m", "pytest", "-m", f"not {REALTIME}", check=False,
                       nice=REST_NICE)
            running = flights.poll() is None
            say(f"the real-time flights' pytest ({shown}){', until it ends' if running else ''}:")
            flown = follow(flights, FLIGHTS_LOG)
        finally:
            stop_group(flights)  # interrupted: no flight left running
    statuses = {"the flights alone": pytest_status(alone), "the rest": pytest_status(rest),
                "the real-time flights": pytest_status(flown)}
    failed = [f"{name} ({status})" for name, status in statuses.items() if status]
    if failed:
        say("failed: " + ", ".join(failed))
    return next((status for status in statuses.values() if status), 0)


def stop_group(process: subprocess.Popen[bytes]) -> None:
    """End ``process``'s process group (its session: :func:`pytest_beside_flights`) and
    reap it: SIGTERM, then after :data:`STOP_GRACE_S` SIGKILL to whatever is left.  A
    flight catches SIGTERM to land cleanly and pytest then starts the next one, so the
    kill is what ends a suite; the group also holds what the flights started."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGTERM)
    with contextlib.suppress(subprocess.TimeoutExpired):
        process.wait(timeout=STOP_GRACE_S)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGKILL)
    process.wait()


def follow(process: subprocess.Popen[bytes], path: Path, every_s: float = 0.5) -> int:
    """Print ``path`` from its start and as ``process`` writes to it, until it exits;
    its exit status."""
    with path.open("rb") as out:
        while True:
            done = process.poll() is not None  # then one last read has all it wrote
            chunk = out.read()
            if chunk:
                sys.stdout.buffer.write(chunk)
                sys.stdout.flush()
            if done:
                return process.wait()
            time.sleep(every_s)


def cmd_lock(args: list[str]) -> int:
    ensure_env("dev")
    run(PY, "-m", "pip", "install", "--quiet", "pip-tools")
    common = ["--quiet", "--generate-hashes", "--strip-extras", "--allow-unsafe",
              "--no-emit-index-url", "--no-emit-find-links", *args]
    # every extra a user may install (postgis, dashboard, mavsdk) is in both locks: the demo's
    # environment serves the dashboard, the tests test all of them
    extras = [arg for name in EXTRAS for arg in ("--extra", name)]
    run(PY, "-m", "piptools", "compile", *common, *extras, "-o", LOCKS["runtime"],
        "pyproject.toml")
    run(PY, "-m", "piptools", "compile", *common, *extras, "--extra", "dev", "-o", LOCKS["dev"],
        "pyproject.toml")
    return 0


COMMANDS = {"demo": cmd_demo, "test": cmd_test, "lock": cmd_lock}


def main() -> int:
    if len(sys.argv) < 2 or sys.argv[1] not in COMMANDS:
        print(__doc__)
        return 2
    os.chdir(ROOT)
    try:
        return COMMANDS[sys.argv[1]](sys.argv[2:])
    except KeyboardInterrupt:  # Ctrl-C: what ran was stopped on the way out
        say("interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
