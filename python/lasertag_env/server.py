"""Starting and stopping a local ``lasertag serve`` for the environments.

The server picks its own port (``LASERTAG_ADDR=127.0.0.1:0``) and logs the address it
bound; reading that line avoids the race of choosing a free port first and having another
process take it. The server gets a random admin token, which lifts the per-address request
rate and match quota (both meant for anonymous clients on a public server) for this
process's environments. Its history database (``LASERTAG_DATA``) goes into a temporary
directory removed when it stops, unless the caller names one.
"""

from __future__ import annotations

import collections
import os
import re
import secrets
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import weakref
from pathlib import Path

__all__ = ["LocalServer", "find_binary", "find_repository", "BinaryNotFound"]

_SERVING = re.compile(r"serving (http://[0-9A-Za-z.\-\[\]:]+)")
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


class BinaryNotFound(FileNotFoundError):
    """No ``lasertag`` binary where the package looks for one."""


def find_repository() -> Path | None:
    """The lasertag repository this package is used from, if any.

    Looked for above this file (an editable install or a source checkout) and above the
    working directory (``pip install ./python`` copies the package elsewhere, but tests and
    scripts usually run from the repository).
    """
    starts = [Path(__file__).resolve().parent, Path.cwd().resolve()]
    for start in starts:
        for d in (start, *start.parents):
            if (d / "Cargo.toml").is_file() and (d / "server").is_dir() and (d / "maps").is_dir():
                return d
    return None


def find_binary(explicit: str | os.PathLike | None = None) -> Path:
    """The ``lasertag`` binary: ``explicit``, else $LASERTAG_BIN, else the repository's
    ``target/release/lasertag`` then ``target/debug/lasertag``, else ``lasertag`` on PATH."""
    tried = []
    if explicit is not None:
        p = Path(explicit)
        if p.is_file() and os.access(p, os.X_OK):
            return p
        raise BinaryNotFound(f"lasertag binary {str(p)!r} does not exist or is not executable")
    env = os.environ.get("LASERTAG_BIN")
    if env:
        p = Path(env)
        if p.is_file() and os.access(p, os.X_OK):
            return p
        raise BinaryNotFound(f"LASERTAG_BIN={env!r} does not exist or is not executable")
    tried.append("$LASERTAG_BIN (unset)")
    repo = find_repository()
    if repo is not None:
        for profile in ("release", "debug"):
            p = repo / "target" / profile / "lasertag"
            if p.is_file() and os.access(p, os.X_OK):
                return p
            tried.append(str(p))
    else:
        tried.append("target/{release,debug}/lasertag of a lasertag repository (none found "
                     "above this package or the working directory)")
    on_path = shutil.which("lasertag")
    if on_path:
        return Path(on_path)
    tried.append("lasertag on PATH")
    raise BinaryNotFound(
        "no lasertag binary found; looked at: " + "; ".join(tried)
        + ". Build it with `cargo build --release` in the repository, or set LASERTAG_BIN, "
        "or pass server='http://host:port' to use a running server."
    )


def _set_parent_death_signal() -> None:  # pragma: no cover - runs in the child
    # Linux: the server gets SIGTERM when the process that started it dies, even by
    # SIGKILL, so a crashed or killed Python never leaves a server behind.
    try:
        import ctypes
        import signal

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
    except Exception:
        pass


class LocalServer:
    """A ``lasertag serve`` child process on a free loopback port.

    ``url`` and ``admin_token`` are what an environment needs; several environments of one
    process may share one server (``parallel_env(server=LocalServer())``). ``close()``
    stops it; so does garbage collection and the interpreter's exit.
    """

    def __init__(
        self,
        binary: str | os.PathLike | None = None,
        maps: str | os.PathLike | None = None,
        env: dict | None = None,
        startup_timeout: float = 60.0,
    ):
        self.binary = find_binary(binary)
        self.admin_token = secrets.token_hex(16)
        child_env = dict(os.environ)
        repo = find_repository()
        if maps is None and "LASERTAG_MAPS" not in child_env and repo is not None:
            maps = repo / "maps"
        if maps is not None:
            child_env["LASERTAG_MAPS"] = str(maps)
        child_env.update(
            LASERTAG_ADDR="127.0.0.1:0",
            LASERTAG_NO_SHOWCASE="true",
            LASERTAG_ADMIN_TOKEN=self.admin_token,
            # The research client owns this server: a match left for a while at a
            # debugger's breakpoint must not be ended as abandoned after 10 minutes.
            LASERTAG_IDLE_MANUAL_AFTER_S="86400",
            RUST_LOG="info,tower_http=warn",
            NO_COLOR="1",
        )
        # Twice as many worker threads as cores: a server with one a core, next to several
        # environment processes on those cores, gets too small a share of them (each of its
        # threads runs one match's step at a time). With 8 environments on 2 cores it made
        # about 10-15% more steps a second; with one environment it makes no difference.
        child_env.setdefault("TOKIO_WORKER_THREADS", str(2 * _cores()))
        child_env.update(env or {})
        # The server records every match it runs (its history, for replays); an
        # environment's thousands of episodes belong to no one's history, and a server
        # started here should leave nothing behind in the working directory.
        data = None
        if "LASERTAG_DATA" not in child_env:
            data = tempfile.mkdtemp(prefix="lasertag-data-")
            child_env["LASERTAG_DATA"] = data
        # Only from the main thread: the parent-death signal fires when the *thread* that
        # started the child ends, which for any other thread is not the process's end.
        preexec = (
            _set_parent_death_signal
            if sys.platform.startswith("linux")
            and threading.current_thread() is threading.main_thread()
            else None
        )
        try:
            self._proc = subprocess.Popen(
                [str(self.binary), "serve"],
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                env=child_env,
                preexec_fn=preexec,
            )
        except BaseException:
            if data is not None:
                shutil.rmtree(data, ignore_errors=True)
            raise
        # The log must be read for as long as the server runs, or a full pipe would block
        # the server's logging; the last lines are kept for error messages.
        # The reading thread holds none of `self`, so that garbage collection can stop the
        # server.
        self._log: collections.deque[str] = collections.deque(maxlen=200)
        found: list[str] = []
        ready = threading.Event()
        threading.Thread(
            target=_drain, args=(self._proc.stdout, self._log, found, ready),
            name="lasertag-server-log", daemon=True,
        ).start()
        self._finalizer = weakref.finalize(self, _stop, self._proc, os.getpid(), data)
        deadline = time.monotonic() + startup_timeout
        while not ready.wait(0.05):
            if self._proc.poll() is not None or time.monotonic() > deadline:
                code = self._proc.poll()
                self.close()
                why = f"exited with code {code}" if code is not None else \
                    f"did not say where it serves within {startup_timeout:.0f} s"
                raise RuntimeError(
                    f"lasertag server {self.binary} {why}; its log:\n" + "\n".join(self._log)
                )
        self.url: str = found[0]

    @property
    def log(self) -> list[str]:
        """The server's last log lines."""
        return list(self._log)

    @property
    def pid(self) -> int:
        return self._proc.pid

    def running(self) -> bool:
        return self._proc.poll() is None

    def close(self) -> None:
        """Stops the server (SIGTERM, then SIGKILL after 5 s); idempotent."""
        self._finalizer()

    def __enter__(self) -> LocalServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "running" if self.running() else "stopped"
        return f"LocalServer({self.url}, {self.binary}, {state})"


def _cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _drain(stream, log: collections.deque, found: list, ready: threading.Event) -> None:
    with stream:
        for raw in stream:
            line = _ANSI.sub("", raw.decode("utf-8", "replace")).rstrip()
            log.append(line)
            if not found:
                m = _SERVING.search(line)
                if m:
                    found.append(m.group(1))
                    ready.set()


def _stop(proc: subprocess.Popen, owner_pid: int, data: str | None = None) -> None:
    # A process forked from the owner (multiprocessing's default on Linux) inherits this
    # object; only the process that started the server stops it.
    if os.getpid() != owner_pid:
        return
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    if data is not None:
        shutil.rmtree(data, ignore_errors=True)
