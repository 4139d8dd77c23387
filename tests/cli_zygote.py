"""Many `python -m pairplay ARGS` processes without paying pairplay's import in each.

Rule: a zygote process imports every module of pairplay once, and matplotlib's pyplot as the verbs
that draw import it (and nothing else: no thread, no socket, no file), then forks one child per command. A child is a whole process of its own, as
`python -m pairplay ARGS` is: its own working folder, stdin from /dev/null, stdout and stderr
to files, `pairplay.__main__` run as __main__ (runpy, as `-m` does), and the interpreter's own
exit (threads joined, atexit handlers, flushes, the final collection; the modules' teardown only where
it has something to do: `_exit`) unless the verb ends with os._exit (the command's `entry` always does:
cli/main.py `_end`; `_exit` is for a non-int exit and test_cli_zygote's own case). Only the import is shared:
what an import prints is checked once, on the zygote's own stderr (`Zygote.import_output`),
where a real start-up would print it before every command.

Why: the command-line mistakes table runs ~70 commands; each paid 0.2-1.6 s of CPU (Python's
start and pairplay's import: numba, zenoh, numpy) for a few milliseconds of work, about 60 s of
CPU of a suite that must finish in minutes on two cores.

`Zygote.start` (and `shared()`, one zygote per test process) forks a long-running command the test talks to
while it runs (a router, a service killed and started again, a session on the bus): `Forked` is what
subprocess.Popen(stdout=PIPE, stderr=PIPE) gives, its streams named pipes (FIFOs) read as it writes. For what the
command does on the bus, not for how it starts or stops: a handled signal (SIGINT, SIGTERM) and start-up keep
their own `python -m pairplay`; SIGKILL is the kernel's, the same to either.

Protocol (JSON lines): request {"id", "args", "cwd", "out", "err", "read_only"} on the zygote's stdin;
replies {"id", "pid"} when forked and {"id", "code", "cpu"} (os.waitstatus_to_exitcode; its CPU
seconds) when it ended.
The zygote is single-threaded (fork is safe), reaps children by polling, and ends at EOF.
"""

from __future__ import annotations

import gc
import importlib
import itertools
import json
import os
import pkgutil
import queue
import selectors
import signal
import subprocess
import sys
import threading
from pathlib import Path


def _preload() -> None:
    """Import every module of pairplay: the CLI's verbs and what they import when they run. The
    subpackages are walked one by one: they live in folders of their own (pyproject's package-dir),
    not under pairplay/."""
    import pairplay.cli.main as cli
    for verb_module, _ in cli.VERBS.values():
        importlib.import_module(verb_module)
    for sub in ("schemas", "core", "replay", "report", "services", "bench", "cli", "gym"):
        package = importlib.import_module(f"pairplay.{sub}")
        for info in pkgutil.walk_packages(package.__path__, f"{package.__name__}."):
            importlib.import_module(info.name)
    for info in pkgutil.iter_modules(importlib.import_module("pairplay").__path__, "pairplay."):
        if info.name != "pairplay.__main__":  # run per command, as `-m` runs it
            importlib.import_module(info.name)
    # pyplot, as the verbs that draw import it (report/plots.py's pyplot, rebuild's curves: Agg): ~1 s of
    # CPU per drawing command (rebuild, sweep, counterfactual, protocol report); it starts no thread
    from pairplay.report.plots import pyplot
    pyplot()


def _read_only(how: str, place: str) -> None:
    """In the forked child: a mount namespace of its own (as `unshare --mount --propagation private`) in which
    `place` is read-only: an empty read-only tmpfs over it ("tmpfs"), or the folder itself bound read-only, its
    files kept ("bind"). Only this child (and what it starts) sees it; the zygote and the test do not."""
    import ctypes
    libc = ctypes.CDLL(None, use_errno=True)
    ms_rdonly, ms_remount, ms_bind, ms_rec, ms_private, clone_newns = 1, 32, 4096, 16384, 1 << 18, 0x20000

    def check(result: int, what: str) -> None:
        if result != 0:
            errno = ctypes.get_errno()
            raise OSError(errno, f"{what}: {os.strerror(errno)}")
    target = place.encode()
    check(libc.unshare(clone_newns), "unshare(CLONE_NEWNS)")
    check(libc.mount(b"none", b"/", None, ms_rec | ms_private, None), "mount --make-rprivate /")
    if how == "tmpfs":
        check(libc.mount(b"tmpfs", target, b"tmpfs", ms_rdonly, None), f"mount -t tmpfs -o ro {place}")
    else:
        check(libc.mount(target, target, None, ms_bind, None), f"mount --bind {place}")
        check(libc.mount(target, target, None, ms_remount | ms_bind | ms_rdonly, None), f"remount,ro,bind {place}")


def _child(request: dict) -> None:
    """In the forked child: become `python -m pairplay ARGS` in its folder; never returns."""
    import runpy
    if request.get("read_only"):
        try:
            _read_only(*request["read_only"])
        except OSError as exc:  # said on the command's stderr, exit 125 (as env/unshare's own failures)
            with open(request["err"], "w") as err:
                err.write(f"cli_zygote: {exc}\n")
            os._exit(125)
    os.chdir(request["cwd"])
    null = os.open(os.devnull, os.O_RDONLY)
    out = os.open(request["out"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    # stderr into stdout's pipe (STDOUT): the one opened end, not the path again (the test unlinks a named pipe
    # once its reader is open: a second open of the path could make a file of that name, read by no one)
    err = os.dup(out) if request["err"] == request["out"] else \
        os.open(request["err"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    for fd, target in ((null, 0), (out, 1), (err, 2)):
        os.dup2(fd, target)
        os.close(fd)
    sys.stdin = open(0, closefd=False)
    if request.get("live"):  # read as it writes (PYTHONUNBUFFERED's purpose for a pipe): a line is sent whole
        sys.stdout.reconfigure(line_buffering=True)
        sys.stderr.reconfigure(line_buffering=True)
    sys.argv = ["pairplay", *request["args"]]
    try:
        runpy.run_module("pairplay", run_name="__main__", alter_sys=True)
        code = 0
    except SystemExit as done:  # (entry ends with os._exit, cli/main.py `_end`: only a non-int exit comes here)
        if done.code is not None and type(done.code) is not int:
            raise  # a message to print: the interpreter's own exit says it
        code = done.code or 0
    _exit(code)


def _exit(code: int) -> None:
    """End the child as the interpreter's exit would (Py_FinalizeEx): non-daemon threads joined, atexit handlers,
    stdout and stderr flushed, the command's garbage collected (its finalizers run); then, if nothing is left for
    the teardown of the modules to do that could be seen, os._exit. That teardown decrefs every object of the
    preloaded modules, which copies each page shared with the zygote: ~0.11 s of CPU a command, 80% of what the
    mistakes table cost (~20 s), for nothing a command does. Left for it, the interpreter's own exit as in
    `python -m pairplay` (SystemExit): an object the command made that has a finalizer (an open file, a socket:
    what the teardown would close or flush; the zygote's gc.freeze undone first: frozen, such an object left in
    a module's global was never finalized), a thread of any kind besides the main one (a zenoh runtime, a
    pool: /proc/self/task), or a flush that fails."""
    import atexit
    import threading
    threading._shutdown()  # as the interpreter: wait for the threads that are not daemons
    atexit._run_exitfuncs()  # (run once: they are cleared)
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except Exception:
        raise SystemExit(code) from None
    gc.collect()  # the command's garbage, not the zygote's (frozen): the final collection's finalizers run here
    ours = {id(sys.stdin), id(sys.stdin.buffer), id(sys.stdin.buffer.raw)}  # _child's own, closefd=False
    if any(hasattr(type(o), "__del__") and id(o) not in ours for o in gc.get_objects()):
        gc.unfreeze()  # (a whole collection at exit, ~0.4 s of CPU: only where a finalizer is left to run)
        raise SystemExit(code)
    if len(os.listdir("/proc/self/task")) > 1:
        raise SystemExit(code)
    os._exit(code)


def serve() -> None:
    _preload()
    gc.freeze()  # the children share the imports' pages: their exit's collection would copy and walk them all
    threads = threading.active_count()
    print(json.dumps({"ready": True, "threads": threads}), flush=True)
    running: dict[int, str] = {}
    selector = selectors.DefaultSelector()
    selector.register(0, selectors.EVENT_READ)
    stdin_open, pending = True, b""
    while stdin_open or running:
        if stdin_open and selector.select(timeout=0.02):
            # the file descriptor itself, not sys.stdin: requests sent at once (commands started from
            # several threads) arrive in one read, and a line left in sys.stdin's buffer was never
            # selected again (its command waited for the next request; the last ones for ever)
            data = os.read(0, 1 << 16)
            stdin_open, pending = bool(data), pending + data
            *lines, pending = pending.split(b"\n")
            for line in lines:
                request = json.loads(line)
                sys.stdout.flush()
                pid = os.fork()
                if pid == 0:
                    selector.close()
                    _child(request)
                running[pid] = request["id"]
                print(json.dumps({"id": request["id"], "pid": pid}), flush=True)
        elif not stdin_open:
            threading.Event().wait(0.02)
        while running:
            pid, status, usage = os.wait4(-1, os.WNOHANG)
            if pid == 0:
                break
            print(json.dumps({"id": running.pop(pid), "code": os.waitstatus_to_exitcode(status),
                              "cpu": usage.ru_utime + usage.ru_stime}), flush=True)


class Zygote:
    """The test side: start the zygote, run commands (from any thread), close it.

    `run(args, cwd, timeout)` returns a subprocess.CompletedProcess (args, returncode, stdout,
    stderr as text); a command still running after `timeout` seconds is killed (SIGKILL) and
    raises subprocess.TimeoutExpired, as subprocess.run does."""

    def __init__(self, env: dict | None = None, scratch: Path | None = None):
        self.scratch = Path(scratch or os.environ.get("TMPDIR", "/tmp"))
        self._err_path = self.scratch / "zygote.stderr"
        self._err = open(self._err_path, "w+")
        here = str(Path(__file__).resolve())
        self.proc = subprocess.Popen([sys.executable, here], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self._err, text=True, env=env)
        ready = json.loads(self.proc.stdout.readline() or "{}")
        if not ready.get("ready"):
            raise RuntimeError(f"the zygote did not start: {self._err_path.read_text()[-2000:]}")
        self.threads = ready["threads"]
        self.cpu = 0.0  # the commands' CPU seconds, children's included
        self.import_output = self._err_path.read_text()
        self._lock = threading.Lock()
        self._next = 0
        self._files = itertools.count(1)  # the commands' file names (next() is atomic)
        self._waiting: dict[str, queue.Queue] = {}
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            reply = json.loads(line)
            with self._lock:
                box = self._waiting.get(reply["id"])
            if box is not None:
                box.put(reply)

    def run(self, args: list[str], cwd: Path, timeout: float = 300,
            read_only: tuple[str, Path] | None = None) -> subprocess.CompletedProcess:
        """`read_only`: ("tmpfs" or "bind", folder): the command runs in a mount namespace of its own in which that
        folder is read-only (_read_only; needs root), as under `unshare --mount --propagation private`."""
        n = next(self._files)
        out, err = self.scratch / f"cmd-{n}.out", self.scratch / f"cmd-{n}.err"
        rid, box, pid = self._send(args, cwd, out, err, read_only)
        try:
            ended = box.get(timeout=timeout)
        except queue.Empty:
            os.kill(pid, 9)
            box.get(timeout=60)
            raise subprocess.TimeoutExpired(["pairplay", *args], timeout, out.read_text(), err.read_text()) from None
        finally:
            with self._lock:
                self._waiting.pop(rid, None)
        result = subprocess.CompletedProcess(["pairplay", *args], ended["code"], out.read_text(), err.read_text())
        self.cpu += ended["cpu"]
        out.unlink()
        err.unlink()
        return result

    def _send(self, args: list[str], cwd: Path, out: Path, err: Path, read_only=None, live=False):
        """Ask for a fork: (request id, its reply queue, the child's pid)."""
        with self._lock:
            self._next += 1
            rid = str(self._next)
            box = self._waiting[rid] = queue.Queue()
        request = {"id": rid, "args": list(args), "cwd": str(cwd), "out": str(out), "err": str(err),
                   "read_only": [read_only[0], str(read_only[1])] if read_only else None, "live": live}
        with self._lock:
            self.proc.stdin.write(json.dumps(request) + "\n")
            self.proc.stdin.flush()
        return rid, box, box.get(timeout=60)["pid"]

    def start(self, args: list[str], cwd: Path | None = None, stdout: int = subprocess.PIPE,
              stderr: int = subprocess.PIPE, text: bool = True) -> "Forked":
        """`python -m pairplay ARGS` forked and running: a Popen-like `Forked`. `stdout` and `stderr` as Popen's:
        subprocess.PIPE (read as it writes), DEVNULL, or for stderr STDOUT (into stdout's pipe)."""
        n = next(self._files)
        paths = {}
        for name, how in (("out", stdout), ("err", stderr)):
            if how == subprocess.DEVNULL:
                paths[name] = Path(os.devnull)
            elif how == subprocess.STDOUT:
                paths[name] = paths["out"]
            else:
                paths[name] = self.scratch / f"live-{n}.{name}"
                os.mkfifo(paths[name])
        rid, box, pid = self._send(args, Path(cwd or os.getcwd()), paths["out"], paths["err"], live=True)
        return Forked(self, ["pairplay", *args], rid, box, pid, paths["out"] if stdout == subprocess.PIPE else None,
                      paths["err"] if stderr == subprocess.PIPE else None, text)

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait(timeout=60)
        self._reader.join(timeout=10)
        self._err.close()
        self._err_path.unlink(missing_ok=True)

    def __enter__(self) -> "Zygote":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Forked:
    """A command the zygote forked, as subprocess.Popen(stdout=PIPE, stderr=PIPE) gives one: `pid`, `stdout`
    and `stderr` (None unless subprocess.PIPE) read as it writes, `poll`, `wait`, `communicate`, `send_signal`,
    `terminate`, `kill`, `returncode` (-N for a signal N, as Popen). Its exit is the zygote's reply: the zygote
    is its parent and reaps it."""

    def __init__(self, zygote: Zygote, args: list[str], rid: str, box: queue.Queue, pid: int, out: Path | None,
                 err: Path | None, text: bool):
        self.args, self.pid, self.returncode = args, pid, None
        self._zygote, self._rid, self._box = zygote, rid, box
        # the child opens its ends first (out, then err): these opens wait for it, in that order
        self.stdout = self._open(out, text) if out is not None else None
        self.stderr = self._open(err, text) if err is not None else None

    def _open(self, fifo: Path, text: bool):
        opened: list = []
        opener = threading.Thread(target=lambda: opened.append(open(fifo, "r" if text else "rb")), daemon=True)
        opener.start()
        opener.join(60)
        if not opened:
            self.kill()
            raise RuntimeError(f"the forked command {self.args} never opened {fifo}")
        fifo.unlink()
        return opened[0]

    def _ended(self, reply: dict) -> int:
        self.returncode = reply["code"]
        self._zygote.cpu += reply["cpu"]
        with self._zygote._lock:
            self._zygote._waiting.pop(self._rid, None)
        return self.returncode

    def poll(self) -> int | None:
        if self.returncode is None:
            try:
                self._ended(self._box.get_nowait())
            except queue.Empty:
                pass
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None:
            try:
                self._ended(self._box.get(timeout=timeout))
            except queue.Empty:
                raise subprocess.TimeoutExpired(self.args, timeout) from None
        return self.returncode

    def communicate(self, timeout: float | None = None) -> tuple:
        """(stdout, stderr) to their ends (stderr None when merged), then the exit, as Popen's."""
        got: dict = {}
        readers = [threading.Thread(target=lambda n=n, f=f: got.__setitem__(n, f.read()), daemon=True)
                   for n, f in (("out", self.stdout), ("err", self.stderr)) if f is not None]
        for reader in readers:
            reader.start()
        for reader in readers:
            reader.join(timeout)
            if reader.is_alive():
                raise subprocess.TimeoutExpired(self.args, timeout)
        self.wait(timeout)
        for f in (self.stdout, self.stderr):
            if f is not None:
                f.close()
        return got.get("out"), got.get("err")

    def send_signal(self, sig: int) -> None:
        if self.poll() is None:  # (once reaped, its pid may be another process's)
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


_SHARED: list[Zygote] = []


def shared() -> Zygote:
    """This test process's zygote (the `pairplay_cli` fixture's too), started at the first call, closed at exit."""
    with _SHARED_LOCK:
        if not _SHARED:
            import atexit
            import shutil
            import tempfile
            scratch = Path(tempfile.mkdtemp(prefix="pairplay-zygote-"))
            zygote = Zygote(scratch=scratch)
            assert zygote.import_output == "" and zygote.threads == 1, (zygote.import_output, zygote.threads)
            _SHARED.append(zygote)
            atexit.register(lambda: (zygote.close(), shutil.rmtree(scratch, ignore_errors=True)))
        return _SHARED[0]


_SHARED_LOCK = threading.Lock()

if __name__ == "__main__":
    serve()
