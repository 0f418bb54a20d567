"""An output folder's safety: writable before any work, held by one run at a time, room checked before
each write, and the write failures h5py reports only as warnings caught (used by the scene lifecycle,
:mod:`clusterdyn.scenes.lifecycle`)."""

import contextlib
import os
import sys
from pathlib import Path

from ..errors import InputError, OutputError

#: lock file in the output folder: one run writes a folder at a time
LOCKFILE = ".clusterdyn.lock"


def check_out(out):
    """Refuse an output folder that cannot be written, before any work (returns a Path or None)."""
    if out is None:
        return None
    p = Path(out)
    if p.exists() and not p.is_dir():
        raise InputError("--out", str(out), "a folder (this path is a file)")
    probe = p
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise InputError("--out", str(out), f"a folder path ({probe} is a file)")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise InputError("--out", str(out), f"a folder you may write to (no write permission in {probe})")
    return p


_HELD = {}          # real path of a locked folder -> [fd, depth]


@contextlib.contextmanager
def lock_out(out):
    """Hold the output folder ``out`` for this process (created if needed) while the block runs.

    An exclusive ``fcntl.flock`` on ``out/.clusterdyn.lock``: a second run (another
    process) writing the same folder is refused in one line (InputError) before it
    touches any file there, so the first run's files are never damaged.  Re-entrant
    within one process (a CLI run that locked the folder, then the scene).  The lock
    goes with the process: a killed run leaves no stale lock.
    """
    if out is None:
        yield None
        return
    import fcntl
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    key = os.path.realpath(out)
    if key in _HELD:
        _HELD[key][1] += 1
        try:
            yield out
        finally:
            _HELD[key][1] -= 1
        return
    path = out / LOCKFILE
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        try:
            who = os.pread(fd, 64, 0).decode(errors="replace").split()
        except OSError:
            who = []
        os.close(fd)
        raise InputError("--out", str(out), "a folder no other clusterdyn run is writing",
                         hint=f"run {'pid ' + who[0] if who else 'of another process'} holds {path}; "
                              "wait for it to end or choose another --out") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    _HELD[key] = [fd, 1]
    try:
        yield out
    finally:
        _HELD[key][1] -= 1
        if _HELD[key][1] == 0:
            del _HELD[key]
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)


class _WriteWatch:
    """Catch the write failures h5py reports only as "Exception ignored" (a chunk written when a
    dataset is released on a full disk): they are recorded here instead of printed, and
    :meth:`check` raises :class:`~clusterdyn.errors.OutputError` for them."""

    def __init__(self):
        self.failures = []
        self._prev = None

    def __enter__(self):
        self._prev = sys.unraisablehook
        sys.unraisablehook = self._hook
        return self

    def __exit__(self, *exc):
        sys.unraisablehook = self._prev

    def _hook(self, u):
        where = f"{u.object!r} {u.err_msg or ''} {u.exc_value}"
        if isinstance(u.exc_value, (OSError, RuntimeError)) and ("h5py" in where or "file write failed" in where):
            self.failures.append(u.exc_value)
            return
        self._prev(u)

    def check(self, path, kept):
        if self.failures:
            exc = self.failures[0]
            self.failures.clear()
            raise OutputError(path, exc, kept)


#: room kept free beyond the estimated size of the next write (HDF5 metadata, allocation in blocks)
WRITE_MARGIN = 1 << 18


def room_for(path, need, kept=None, fresh=False):
    """Raise :class:`~clusterdyn.errors.OutputError` (ENOSPC or EFBIG) unless ``need`` more bytes fit
    in ``path`` (its file system's free space for us and the process's file-size limit), checked
    *before* writing: HDF5 cannot always recover a file whose write failed half way, so a
    run stops while its files are whole.  ``fresh``: the bytes go to a new file that replaces
    ``path`` once complete (a checkpoint), so its present size does not count."""
    import errno
    import resource
    path = Path(path)
    folder = path.parent if not path.is_dir() else path
    size = path.stat().st_size if (path.is_file() and not fresh) else 0     # fresh: a new file replaces it
    try:
        st = os.statvfs(folder)
        free = st.f_bavail * st.f_frsize
    except OSError:  # pragma: no cover - no statvfs
        free = None
    if free is not None and free < need + WRITE_MARGIN:
        raise OutputError(path, OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)),
                          (kept + "; " if kept else "") + f"{free / 2**20:.3g} MiB free, the next write needs "
                          f"about {(need + WRITE_MARGIN) / 2**20:.3g} MiB")
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if soft != resource.RLIM_INFINITY and size + need + WRITE_MARGIN > soft:
        raise OutputError(path, OSError(errno.EFBIG, os.strerror(errno.EFBIG)),
                          (kept + "; " if kept else "") + f"the file-size limit is {soft / 2**20:.3g} MiB")


def _write_failure(exc):
    """An exception that means a file could not be written (not bad input, not physics)."""
    from ase.calculators.calculator import CalculationFailed
    return isinstance(exc, (OSError, RuntimeError)) and not isinstance(exc, (CalculationFailed, InputError))
