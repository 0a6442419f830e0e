"""Helpers of the fault tests: the CLI in-process with its one stderr line, a small file
system (a tmpfs when this process may mount one) and a file-size limit for a subprocess."""

from __future__ import annotations

import contextlib
import os
import resource
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from companion.cli import main

ROOT = Path(__file__).resolve().parents[1]
#: An EKF origin and the sample map: what ``companion run`` needs before it opens anything.
FLIGHT = ("--set", "mavlink.origin_lat_deg=47.3977", "--set", "mavlink.origin_lon_deg=8.5456",
          "--set", f'landmarks.map_path="{ROOT / "config" / "landmarks.geojson"}"',
          "--set", 'source.kind="sim"', "--set", 'source.spec="survey"')


def one_line_failure(capsys: pytest.CaptureFixture[str], argv: list[str], status: int) -> str:
    """Run ``companion ARGV`` in this process: it returns ``status`` (never raises, so no
    traceback) and prints exactly one line on stderr, which is returned."""
    got = main(["--log-level", "error", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert got == status, err
    assert len(err) == 1, err
    assert "Traceback" not in err[0]
    return err[0]


def limit_file_size(max_bytes: int) -> Callable[[], None]:
    """``preexec_fn`` for a subprocess whose files may not grow past ``max_bytes``: a write
    beyond fails with EFBIG (Python ignores SIGXFSZ), as a full disk fails with ENOSPC."""
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (max_bytes, max_bytes))
    return apply


def companion_process(*args: str, cwd: Path, max_file_bytes: int | None = None,
                      timeout_s: float = 90) -> subprocess.CompletedProcess[str]:
    """``python -m companion ARGS`` to the end (optionally under a file-size limit)."""
    return subprocess.run(
        [sys.executable, "-m", "companion", *args], cwd=cwd, capture_output=True, text=True,
        timeout=timeout_s, check=False, env={**os.environ, "PYTHONPATH": str(ROOT)},
        preexec_fn=None if max_file_bytes is None else limit_file_size(max_file_bytes))


@contextlib.contextmanager
def small_filesystem(where: Path, size_kib: int) -> Iterator[Path | None]:
    """A tmpfs of ``size_kib`` mounted at ``where`` when this process may mount one (root,
    as in CI); None otherwise (the caller then uses a file-size limit instead)."""
    mount, umount = shutil.which("mount"), shutil.which("umount")
    where.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or mount is None or umount is None:
        print(f"no small file system: not root or no mount ({os.geteuid()=})")
        yield None
        return
    done = subprocess.run([mount, "-t", "tmpfs", "-o", f"size={size_kib}k", "tmpfs",
                           str(where)], capture_output=True, text=True, check=False)
    if done.returncode != 0:
        print(f"no small file system: mount refused: {done.stderr.strip()}")
        yield None
        return
    try:
        yield where
    finally:
        subprocess.run([umount, "-l", str(where)], check=False)


@contextlib.contextmanager
def plain_directory(where: Path) -> Iterator[Path]:
    """``where`` itself, used where :func:`small_filesystem` would be (file-size limit case)."""
    where.mkdir(parents=True, exist_ok=True)
    yield where


def remount_read_only(where: Path) -> None:
    """Make the tmpfs at ``where`` read-only (root only: see :func:`small_filesystem`)."""
    subprocess.run(["mount", "-o", "remount,ro", str(where)], check=True)
